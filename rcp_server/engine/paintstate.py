"""The data a painting hands from one iteration to the next: per-pixel channels of a region.

Its own module, below everything that paints, so that the tile loop (``painting/loop.py``) and both methods
(``raytrace.py``, ``imagespace.py``) share it without importing each other.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..camera.camera import Region
from ..util.stopwatch import Stopwatch

CHANNELS = ("color", "depth", "normal", "direction", "geometric", "object", "material", "albedo", "uv", "position")
"""The per-pixel channels of :class:`PaintState`, in its field order: what a mapping may read (the paper's
section 2: colour, z-depth, shading and surface normal, material, object ID, and what a ray saw)."""

SCALAR_CHANNELS = ("depth", "object", "material")
"""The channels of one number per pixel (object and material: an index as a float32, -1 on a miss)."""


class Abandoned(Exception):
    """A painting stopped between iterations because its ``should_stop`` said so (the camera moved on)."""


def channel_shape(name: str, pixels: int) -> tuple[int, ...]:
    """The shape of channel ``name`` for ``pixels`` pixels: :data:`SCALAR_CHANNELS` one number per pixel, uv
    two, the others three."""
    if name in SCALAR_CHANNELS:
        return (pixels,)
    return (pixels, 2) if name == "uv" else (pixels, 3)


@dataclass
class PaintState:
    """Per-pixel data of one iteration for a region, row-major. Channels not recorded are None.

    color : (n, 3) float32 in [0, 1];  depth : (n,) float32 view depth;  normal : (n, 3) float32 shading
    normal, 0 on a miss;  direction : (n, 3) float32 ray direction;  geometric : (n, 3) float32 the hit
    triangle's own normal, on the shading normal's side;  object, material : (n,) float32 index into the
    scene's objects and materials (``scene.Geometry``), -1 on a miss;  albedo : (n, 3) float32 the surface's
    unlit colour (texture included), the sky's colour on a miss;  uv : (n, 2) float32 texture coordinates, 0
    on a miss;  position : (n, 3) float32 world point seen (NaN on a miss, and on a pixel
    whose samples saw the sky in part: the sky has no point).
    Samples average, but object and material are the first sample's.
    """

    region: Region
    color: np.ndarray
    depth: np.ndarray | None = None
    normal: np.ndarray | None = None
    direction: np.ndarray | None = None
    geometric: np.ndarray | None = None
    object: np.ndarray | None = None
    material: np.ndarray | None = None
    albedo: np.ndarray | None = None
    uv: np.ndarray | None = None
    position: np.ndarray | None = None
    blank: bool = False  # I_0: the mid-grey canvas that moves no ray

    @classmethod
    def canvas(cls, region: Region) -> PaintState:
        return cls(region, np.full((region.pixel_count, 3), 0.5, np.float32), blank=True)

    @classmethod
    def empty(cls, region: Region, channels) -> PaintState:
        """Uninitialised buffers for color and every other channel named in ``channels``."""
        n = region.pixel_count
        arrays: dict[str, Any] = {  # PaintState's keyword arguments
            name: np.empty(channel_shape(name, n), np.float32) if name == "color" or name in channels else None
            for name in CHANNELS
        }
        return cls(region, **arrays)

    def recorded(self) -> frozenset[str]:
        """The channels this state holds."""
        return frozenset(name for name in CHANNELS if getattr(self, name) is not None)

    def has(self, channels) -> bool:
        return all(getattr(self, name) is not None for name in channels)

    def image(self) -> np.ndarray:
        """The painting, (h, w, 3) float32 in [0, 1]."""
        return self.color.reshape(self.region.height, self.region.width, 3)

    def rows(self, tile: Region) -> PaintState:
        """The part of this state that covers ``tile`` (full-width rows of this region)."""
        a = (tile.y0 - self.region.y0) * self.region.width
        b = a + tile.pixel_count
        return PaintState(tile, blank=self.blank, **self._pick(slice(a, b)))

    def first(self, n: int, region: Region) -> PaintState:
        """This state's first ``n`` pixels, as a state of ``region`` (of ``n`` pixels): views to write into."""
        return PaintState(region, blank=self.blank, **self._pick(slice(n)))

    def write_into(self, target: PaintState) -> None:
        """Copy this state's values into ``target`` (of as many pixels), channel by channel: every channel
        ``target`` holds must be here."""
        for name in CHANNELS:
            out = getattr(target, name)
            if out is not None:
                out[...] = getattr(self, name)

    def paste_color(self, image: np.ndarray) -> None:
        """Write this state's color into ``image`` (H, W, 3) float32 of the full image, at this region's rows
        (a region of full-width rows)."""
        a = self.region.y0 * self.region.width
        image.reshape(-1, 3)[a : a + self.region.pixel_count] = self.color

    def resized(self, width: int, height: int) -> PaintState:
        """This state (of a full image) at another size, nearest pixel: a walk-through that changes its
        resolution keeps painting where it was instead of starting over from the canvas."""
        src = self.region
        if (width, height) == (src.width, src.height):
            return self
        x = np.minimum((np.arange(width) + 0.5) * src.width / width, src.width - 1).astype(np.int64)
        y = np.minimum((np.arange(height) + 0.5) * src.height / height, src.height - 1).astype(np.int64)
        pick = (y[:, None] * src.width + x[None, :]).ravel()
        return PaintState(Region(width, height), blank=self.blank, **self._pick(pick))

    def gathered(self, index: np.ndarray) -> PaintState:
        """A state of the same region whose pixel ``k`` holds this state's pixel ``index[k]`` ((n,) int64)."""
        return PaintState(self.region, blank=self.blank, **self._pick(index))

    def _pick(self, index) -> dict[str, Any]:  # channel -> its rows, or None: PaintState's keyword arguments
        return {name: None if getattr(self, name) is None else getattr(self, name)[index] for name in CHANNELS}


TileIteration = Callable[[PaintState, Stopwatch], PaintState]
"""The tile interface both methods lend (``raytrace.TracedTile``, ``imagespace.LookupTile``): one
iteration ``I_{n-1} -> I_n`` of one tile, its stages timed on the stopwatch. The painting runs it."""
