"""Writing a sequence of paintings: H.264 in an MP4 file (through PyAV, whose wheels ship FFmpeg with
libx264), or numbered PNG files. Frames arrive as the engine's float images and become uint8 here, through
:func:`images.to_uint8`, exactly as a still does.

An MP4 is written beside its destination under a temporary name and moved into place when complete, so a
failure (a full disk, a cancelled job) leaves no half-written video and never replaces a good one.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Protocol

import numpy as np

from ..camera.camera import PROJECTIONS, STEREO
from ..util import images
from . import spherical

VIDEO_FORMATS = {".mp4": "mp4"}
CRF = 18
"""x264's constant rate factor: 18 is about visually lossless, which a painting's fine strokes need."""


class FrameWriter(Protocol):
    """Where a sequence's frames go, in order; ``close`` completes it, ``abort`` drops what is incomplete."""

    def write(self, image: np.ndarray) -> None: ...

    def close(self) -> None: ...

    def abort(self) -> None: ...


def is_video(out: Path) -> bool:
    return Path(out).suffix.lower() in VIDEO_FORMATS


def check_video_size(width: int, height: int) -> None:
    """H.264 in yuv420p halves the color resolution both ways: refuse odd sizes (``ValueError``) up front."""
    if width % 2 or height % 2:
        raise ValueError(f"an MP4 (H.264, yuv420p) needs an even width and height, got {width}x{height}")


class Mp4Writer:
    """H.264 (yuv420p, CRF :data:`CRF`) in MP4 with its index at the front, so a browser plays it while it
    downloads. ``fps`` may be fractional (23.976 is written as 24000/1001). An ``equirect`` painting's video
    carries the spherical-video metadata (``spherical.py``) of its ``stereo`` layout, so that 360° players
    and headsets show it all around."""

    def __init__(
        self, out: Path, width: int, height: int, fps: float, projection: str = "perspective", stereo: str = "mono"
    ):
        import av  # the video writer's own dependency: importing it costs a quarter of a second

        check_video_size(width, height)
        if projection not in PROJECTIONS or stereo not in STEREO:
            raise ValueError(f"no video of projection {projection!r} in stereo {stereo!r}")
        self.spherical = stereo if projection == "equirect" else None  # a perspective video is a flat one
        self.out = Path(out)
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self._partial = self.out.with_name(f".{self.out.name}.part")
        self._av = av
        self._partial.unlink(missing_ok=True)  # whatever had its name (a link among them): written anew, not through
        try:
            self._container = av.open(str(self._partial), "w", format="mp4", options={"movflags": "faststart"})
            self._stream = self._container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
            self._stream.width, self._stream.height = width, height
            self._stream.pix_fmt = "yuv420p"
            self._stream.options = {"crf": str(CRF)}
        except av.FFmpegError as exc:
            self._partial.unlink(missing_ok=True)
            raise OSError(f"{self.out}: cannot write a video: {exc}") from None
        self.frames = 0

    def write(self, image: np.ndarray) -> None:
        frame = self._av.VideoFrame.from_ndarray(images.to_uint8(image), format="rgb24")
        self._mux(self._stream.encode(frame))
        self.frames += 1

    def _mux(self, packets) -> None:
        try:
            self._container.mux(packets)
        except self._av.FFmpegError as exc:  # a full disk, mostly
            raise OSError(f"{self.out}: cannot write the video: {exc}") from None

    def size(self) -> int:
        """Bytes written so far (none until the encoder's first packets: the file opens with them)."""
        for file in (self._partial, self.out):
            if file.exists():
                return file.stat().st_size
        return 0

    def close(self) -> None:
        try:
            self._mux(self._stream.encode(None))  # flush the encoder's delayed frames
            self._container.close()
            if self.spherical is not None:
                flat = self._partial.with_name(self._partial.name + ".flat")
                os.replace(self._partial, flat)
                try:
                    spherical.add_spherical(flat, self._partial, self.spherical)
                finally:
                    flat.unlink(missing_ok=True)
        except BaseException:
            self.abort()
            raise
        os.replace(self._partial, self.out)

    def abort(self) -> None:
        try:
            self._container.close()
        except Exception:  # already broken: the partial file goes either way
            pass
        self._partial.unlink(missing_ok=True)


class ImageFrames:
    """One image file per frame, named by ``name_of(index)`` (PNG or JPEG by its suffix, at JPEG ``quality``);
    every file is complete when written."""

    def __init__(self, name_of: Callable[[int], Path], quality: int = 92):
        self._name_of = name_of
        self._quality = quality
        self.frames = 0

    def write(self, image: np.ndarray) -> None:
        images.save(self._name_of(self.frames), image, self._quality)
        self.frames += 1

    def close(self) -> None:
        pass

    def abort(self) -> None:
        pass


def frame_names(folder: Path, count: int) -> Callable[[int], Path]:
    """``folder/frame_0000.png``, ...: four digits, or as many as ``count - 1`` needs (ffmpeg's ``%04d``)."""
    digits = max(4, len(str(max(count - 1, 0))))
    return lambda index: Path(folder) / f"frame_{index:0{digits}d}.png"


def open_writer(
    out: Path, width: int, height: int, fps: float, count: int, projection: str = "perspective", stereo: str = "mono"
) -> FrameWriter:
    """An MP4 for ``*.mp4`` (an ``equirect`` one with the spherical metadata of its ``stereo`` layout);
    numbered PNGs in ``out`` when it is a folder (an existing one, or a path ending in a separator or without
    a suffix). Raises ``ValueError`` for anything else."""
    out = Path(out)
    if is_video(out):
        return Mp4Writer(out, width, height, fps, projection, stereo)
    if is_folder(out):
        out.mkdir(parents=True, exist_ok=True)
        return ImageFrames(frame_names(out, count))
    raise ValueError(f"{out}: a sequence goes to an .mp4 file or a folder of PNG frames")


def is_folder(out) -> bool:
    """Whether ``out`` names a folder: an existing one, a path written with a trailing separator, or no suffix."""
    text = os.fspath(out)
    return Path(out).is_dir() or text.endswith(("/", os.sep)) or Path(out).suffix == ""
