"""Radiance HDR (``.hdr``, RGBE) panoramas, which Pillow cannot read, and their tonemap to display colors.

The painting reads displayed, low-dynamic-range colors (MISSION.md), so a panorama is tonemapped once,
when the scene loads: ``display = (1 - exp(-2^exposure * radiance)) ^ (1 / 2.2)``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numba
import numpy as np

_RESOLUTION = re.compile(rb"^-Y (\d+) \+X (\d+)$")


class RadianceError(ValueError):
    """A file that is not a readable Radiance picture; the message names it."""


@numba.njit(cache=True, nogil=True)
def _decode(data, start, width, height, out):
    """Run-length-encoded RGBE scanlines (or flat ones) from data[start:] into out (height, width, 4) uint8.
    Returns the number of bytes read, or -1 if the data ends early or is malformed."""
    p = start
    n = len(data)
    for row in range(height):
        if p + 4 <= n and data[p] == 2 and data[p + 1] == 2 and (data[p + 2] << 8 | data[p + 3]) == width:
            p += 4
            for channel in range(4):
                col = 0
                while col < width:
                    if p >= n:
                        return -1
                    count = int(data[p])
                    p += 1
                    if count > 128:  # a run of one value
                        count -= 128
                        if count > width - col or p >= n:
                            return -1
                        for k in range(count):
                            out[row, col + k, channel] = data[p]
                        p += 1
                    else:  # count literal values
                        if count == 0 or count > width - col or p + count > n:
                            return -1
                        for k in range(count):
                            out[row, col + k, channel] = data[p + k]
                        p += count
                    col += count
        else:  # a flat scanline: width RGBE quadruples
            if p + 4 * width > n:
                return -1
            for col in range(width):
                for channel in range(4):
                    out[row, col, channel] = data[p + 4 * col + channel]
            p += 4 * width
    return p - start


def read_radiance(path: Path) -> np.ndarray:
    """Linear radiance of a Radiance ``.hdr`` picture (top row first): (h, w, 3) float32."""
    path = Path(path)
    try:
        data = np.frombuffer(path.read_bytes(), dtype=np.uint8)
    except OSError as exc:
        raise RadianceError(f"{path}: cannot read ({exc.strerror})") from None
    raw = data.tobytes()
    if not (raw.startswith(b"#?RADIANCE") or raw.startswith(b"#?RGBE")):
        raise RadianceError(f"{path}: not a Radiance picture (no #?RADIANCE header)")
    end = raw.find(b"\n\n")
    if end < 0:
        raise RadianceError(f"{path}: the header never ends")
    header = raw[:end].split(b"\n")
    fmt = [line for line in header if line.startswith(b"FORMAT=")]
    if fmt and fmt[0] != b"FORMAT=32-bit_rle_rgbe":
        raise RadianceError(f"{path}: unsupported {fmt[0].decode(errors='replace')} (only 32-bit_rle_rgbe)")
    line_end = raw.find(b"\n", end + 2)
    match = _RESOLUTION.match(raw[end + 2 : line_end]) if line_end > 0 else None
    if match is None:
        raise RadianceError(f"{path}: only the usual '-Y height +X width' orientation is supported")
    height, width = int(match.group(1)), int(match.group(2))
    if not (0 < width <= 32768 and 0 < height <= 32768):
        raise RadianceError(f"{path}: implausible size {width}x{height}")
    rgbe = np.zeros((height, width, 4), np.uint8)
    if _decode(data, line_end + 1, width, height, rgbe) < 0:
        raise RadianceError(f"{path}: the pixel data is truncated or malformed")
    exponent = rgbe[..., 3].astype(np.int32)
    scale = np.where(exponent > 0, np.ldexp(1.0, exponent - (128 + 8)), 0.0)
    return (rgbe[..., :3] * scale[..., None]).astype(np.float32)


def tonemap(radiance: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Display colors in [0, 1] from linear radiance: exponential tonemap, then gamma 2.2; (h, w, 3) float32."""
    finite = np.nan_to_num(radiance, nan=0.0, posinf=float(np.finfo(np.float32).max), neginf=0.0)
    with np.errstate(over="ignore"):
        exposed = np.float32(2.0**exposure) * finite
    return np.power(1.0 - np.exp(-np.maximum(exposed, 0.0)), 1.0 / 2.2).astype(np.float32)
