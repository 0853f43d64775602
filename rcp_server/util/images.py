"""Encoding paintings to files and bytes: the only place float images become uint8."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}


def to_uint8(image: np.ndarray) -> np.ndarray:
    """(h, w, 3) float in [0, 1] -> (h, w, 3) uint8, rounding to nearest; uint8 (encoded already, as frames
    from Ray are) passes unchanged."""
    if image.dtype == np.uint8:
        return image
    return (np.clip(np.nan_to_num(image, nan=0.0), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def encode(image: np.ndarray, fmt: str = "PNG", quality: int = 90) -> bytes:
    buffer = io.BytesIO()
    # at 90 and above keep full-resolution color (4:4:4): halving it smears a painting's colored strokes
    options = {"quality": quality, "subsampling": 0 if quality >= 90 else 2} if fmt == "JPEG" else {"compress_level": 6}
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
