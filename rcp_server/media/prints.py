"""Stills at print size: a painting of up to :data:`MAX_SIDE` pixels a side, painted in bands of rows and
written to a PNG as the bands come, so that memory stays bounded whatever the size.

A band is a crop of the whole painting (``painting.paint``'s ``region``: every pixel reads only its own
previous value), so the picture is exactly the painting in one piece. Each band holds at most
:data:`BAND_PIXELS` pixels; the PNG's rows are compressed (zlib, as the format says) and written as IDAT
chunks as they arrive: nothing of the picture is kept after its band.

``alpha``: an RGBA PNG whose alpha is 0 where the plain image (the first iteration) sees no geometry (every
sample of the pixel missed; a cut-out texel is no geometry) and 1 elsewhere. ``bits``: 8 (the encoder's
rounding of every still, ``images.to_uint8``) or 16 (``round(v * 65535)``) a channel.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..camera.camera import Camera, Region
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util import images

MAX_SIDE = 16384
"""The widest and tallest print, pixels."""
BAND_PIXELS = 1 << 19
"""Pixels a band holds at most (the painting's state, its plain pass for alpha and its rows: tens of MB)."""
BITS = (8, 16)

BandPainter = Callable[[Region, PaintParams], object]
"""Paints one band: ``(region, params) -> PaintResult`` (``painting.paint`` or a workshop's, bound to the scene,
camera, size and time)."""


def check_print(width: int, height: int, params: PaintParams, bits: int) -> None:
    """``ValueError`` in one line for a print that cannot be made."""
    if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
        raise ValueError(f"a print is at most {MAX_SIDE}x{MAX_SIDE} pixels, got {width}x{height}")
    if bits not in BITS:
        raise ValueError(f"a print has 8 or 16 bits a channel, got {bits}")
    if params.method == "image" and width * height > BAND_PIXELS:
        raise ValueError(
            "a print this large is painted in bands, and the image method needs the whole picture at once: "
            "use method raytrace"
        )


def bands(width: int, height: int) -> list[Region]:
    """Bands of whole rows, each at most :data:`BAND_PIXELS` pixels (one row at least), top to bottom."""
    rows = max(1, BAND_PIXELS // width)
    return Region(width, height).tiles(rows)


class PngWriter:
    """A PNG written row band by row band: 8 or 16 bits, RGB or RGBA, non-interlaced; to a hidden name beside
    ``out`` and moved into place by :meth:`close` (a failure or a cancel leaves nothing half written)."""

    def __init__(self, out: Path, width: int, height: int, bits: int = 8, alpha: bool = False):
        self.out = Path(out)
        self.width, self.height, self.bits, self.alpha = width, height, bits, alpha
        self.channels = 4 if alpha else 3
        self.rows = 0
        self._partial = self.out.with_name(f".{self.out.name}.part")
        self._partial.unlink(missing_ok=True)
        self._file = open(self._partial, "xb")  # noqa: SIM115  (closed by close or abort)
        self._zip = zlib.compressobj(6)
        self._file.write(b"\x89PNG\r\n\x1a\n")
        colour = 6 if alpha else 2
        self._chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, bits, colour, 0, 0, 0))

    def _chunk(self, kind: bytes, data: bytes) -> None:
        self._file.write(struct.pack(">I", len(data)) + kind + data)
        self._file.write(struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    def write(self, rows: np.ndarray) -> None:
        """Rows ``(n, width, channels)``, uint8 or (16 bits) uint16, top to bottom after those written."""
        dtype = np.dtype(">u2") if self.bits == 16 else np.dtype(np.uint8)
        rows = np.ascontiguousarray(rows, dtype=dtype).reshape(len(rows), -1)
        lines = np.concatenate([np.zeros((len(rows), 1), np.uint8), rows.view(np.uint8)], axis=1)  # filter 0
        packed = self._zip.compress(lines.tobytes())
        if packed:
            self._chunk(b"IDAT", packed)
        self.rows += len(rows)

    def close(self) -> None:
        if self.rows != self.height:
            self.abort()
            raise ValueError(f"a PNG of {self.height} rows was given {self.rows}")
        try:
            self._chunk(b"IDAT", self._zip.flush())
            self._chunk(b"IEND", b"")
            self._file.close()
            os.replace(self._partial, self.out)
        except BaseException:
            self.abort()
            raise

    def size(self) -> int:
        return self._file.tell() if not self._file.closed else 0

    def abort(self) -> None:
        self._file.close()
        self._partial.unlink(missing_ok=True)


def encoded(image: np.ndarray, bits: int) -> np.ndarray:
    """A float image's values as the print stores them: uint8 as every still, or uint16."""
    if bits == 8:
        return images.to_uint8(image)
    return np.round(np.clip(np.nan_to_num(image), 0.0, 1.0) * 65535.0).astype(np.uint16)


def coverage(scene: Scene, camera: Camera, params: PaintParams, paint_band: BandPainter, band: Region, time: float):
    """Where the plain image of ``band`` sees geometry: (rows, width) bool (a pixel some sample of which hit)."""
    plain = replace(params, iterations=1, mapping="depth", lambda_p=0.0, lambda_e=0.0, objects=(), materials=())
    z_max = params.z_max if params.z_max is not None else scene.depth_of_miss(camera.eye, time)
    plain = replace(plain, z_max=z_max)
    depth = paint_band(band, plain).state.depth  # type: ignore[attr-defined]
    return (depth < np.float32(z_max)).reshape(band.height, band.width)


def print_bands(
    scene: Scene,
    camera: Camera,
    width: int,
    height: int,
    params: PaintParams,
    paint_band: BandPainter,
    *,
    time: float = 0.0,
    bits: int = 8,
    alpha: bool = False,
) -> Iterator[np.ndarray]:
    """The print's rows, band by band: (rows, width, 3 or 4) uint8 or uint16."""
    check_print(width, height, params, bits)
    top = 65535 if bits == 16 else 255
    for band in bands(width, height):
        image = paint_band(band, params).image  # type: ignore[attr-defined]
        rows = encoded(image, bits)
        if alpha:
            seen = coverage(scene, camera, params, paint_band, band, time)
            rows = np.concatenate([rows, np.where(seen, top, 0).astype(rows.dtype)[..., None]], axis=2)
        yield rows


def write_print(out: Path, rows: Iterator[np.ndarray], width: int, height: int, bits: int, alpha: bool,
                progress: Callable[[int], None] | None = None) -> None:  # fmt: skip
    """Rows as they come into the PNG ``out``; ``progress(rows)`` after each band."""
    writer = PngWriter(out, width, height, bits, alpha)
    try:
        for band in rows:
            writer.write(band)
            if progress is not None:
                progress(len(band))
    except BaseException:
        writer.abort()
        raise
    writer.close()
