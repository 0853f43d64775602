"""A film's files in the data folder: its frames as lossless PNGs (and a temporal film's state) while it paints,
read back to assemble its MP4, and the bytes they take (what ``RCP_VIDEO_DISK_BYTES`` counts)."""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import numpy as np
from PIL import Image

from .store import UnsafeFile, open_regular, regular_size


class DamagedFrame(ValueError):
    """A frame kept in the data folder that is not the image it should be; the message gives its number only."""


def save_png(image: np.ndarray, sink: BinaryIO) -> None:
    Image.fromarray(image).save(sink, "PNG", compress_level=1)  # lossless, and fast: a frame waits for it


def state_bytes(width: int, height: int) -> int:
    """The most a temporal job's kept state may take: every channel of every pixel, with room to spare."""
    return 1024 * width * height + (1 << 20)


def kept_frame(frames_dir: Path, index: int, width: int, height: int) -> np.ndarray:
    """Frame ``index`` as kept in ``frames_dir``, (height, width, 3) uint8; :class:`DamagedFrame` (or
    ``UnsafeFile``) for one that is not a PNG of that size."""
    try:
        with open_regular(frame_file(frames_dir, index), 4 * width * height + (1 << 20)) as source:
            with Image.open(source) as frame:
                if frame.size != (width, height):
                    raise ValueError
                return np.asarray(frame.convert("RGB"))
    except UnsafeFile:
        raise
    except (OSError, ValueError, Image.DecompressionBombError):
        raise DamagedFrame(f"frame {index} kept in the data folder is damaged; ask for the video again") from None


def frame_file(frames_dir: Path, index: int) -> Path:
    return frames_dir / f"frame_{index:06d}.png"


def folder_bytes(folder: Path) -> int:
    """Bytes of the regular files in ``folder`` (0 when there is none)."""
    try:
        return sum(regular_size(f) or 0 for f in folder.iterdir())
    except OSError:
        return 0


def file_bytes(file: Path) -> int:
    return regular_size(file) or 0  # 0: deleted meanwhile (or not a file of its own)
