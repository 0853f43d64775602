"""Encoding paintings to files and bytes: the only place float images become uint8."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}


ROWS_AT_ONCE = 1 << 16  # numbers of a picture converted at a time by to_uint8


def to_uint8(image: np.ndarray) -> np.ndarray:
    """(h, w, 3) float in [0, 1] -> (h, w, 3) uint8, rounding to nearest; uint8 (encoded already, as frames
    from Ray are) passes unchanged."""
    if image.dtype == np.uint8:
        return image
    out = np.empty(image.shape, np.uint8)
    rows = max(1, ROWS_AT_ONCE // max(1, image[0].size))
    for y in range(0, len(image), rows):  # a band at a time: float temporaries of a whole picture cost 12 B a pixel
        band = np.nan_to_num(image[y : y + rows], nan=0.0)
        np.clip(band, 0.0, 1.0, out=band)
        band *= 255.0
        band += 0.5
        out[y : y + rows] = band
    return out


def encode(image: np.ndarray, fmt: str = "PNG", quality: int = 90) -> bytes:
    buffer = io.BytesIO()
    # full-resolution color (4:4:4) at every quality, walk frames too: halving it smears a painting's colored
    # strokes, and alone capped a walk frame near 29 dB against the exact picture whatever the renderer did
    options = {"quality": quality, "subsampling": 0} if fmt == "JPEG" else {"compress_level": 6}
    Image.fromarray(to_uint8(image), "RGB").save(buffer, fmt, **options)
    return buffer.getvalue()


def image_format(path: Path) -> str:
    try:
        return FORMATS[Path(path).suffix.lower()]
    except KeyError:
        raise ValueError(f"{path}: unknown image type; use one of {', '.join(FORMATS)}") from None


def save(path: Path, image: np.ndarray, quality: int = 92) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(encode(image, image_format(path), quality))
