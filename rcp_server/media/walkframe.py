"""A walk frame: what one frame of a walk-through needs, as one frozen record, and its painting (paint, keep the
state, encode), written once for the server's threads and for a walk actor on Ray alike.

A walker's painter keeps the last frame's per-pixel state (:class:`WalkCanvas`), so a frame says only which
frame it continues from (``after``): a state that is not that one (a frame the walk threw away, a painter
started afresh) starts the recursion again from ``I_0``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..camera.camera import Camera
from ..painting.loop import PaintResult, PaintState
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util import images


@dataclass(frozen=True)
class WalkFrame:
    """One walk frame to paint.

    width, height : the painting's size in pixels (both eyes of a stereo pair); time : scene seconds; quality :
    the JPEG's; serial : the frame's number in its walk; after : the frame whose state it continues from
    (temporal), None to start from ``I_0``."""

    scene: Scene
    camera: Camera
    width: int
    height: int
    params: PaintParams
    time: float
    quality: int
    serial: int
    after: int | None = None


@dataclass(frozen=True)
class WalkPainted:
    """A walk frame painted and encoded: its JPEG, its size (both eyes), whether it went on from the kept state
    (``continued``), the seconds it took as its caller times it, and (when asked for) its pixels,
    (height, width, 3) uint8."""

    jpeg: bytes
    width: int
    height: int
    serial: int
    continued: bool
    seconds: float
    pixels: np.ndarray | None = None
    bands: tuple[tuple[int, int, bytes], ...] = ()  # painted in bands on a crew: each (first row, rows, its JPEG)


Paint = Callable[..., PaintResult]
"""``paint(scene, camera, width, height, params, time=..., previous=...)``: ``painting.paint`` with the caller's
pool, threads, stop and buffers bound."""


class WalkCanvas:
    """One walker's kept state: the last frame painted (``serial``) and its per-pixel data."""

    def __init__(self) -> None:
        self.serial: int | None = None
        self.state: PaintState | None = None

    def paint(self, frame: WalkFrame, paint: Paint, keep_pixels: bool = False) -> WalkPainted:
        """Blocking: paint ``frame`` (from the kept state when it continues it), keep its state, encode it."""
        clock = time.perf_counter()
        continued = frame.after is not None and self.serial == frame.after and self.state is not None
        previous = self.state.resized(frame.width, frame.height) if continued and self.state is not None else None
        size = (frame.width, frame.height)
        result = paint(frame.scene, frame.camera, *size, frame.params, time=frame.time, previous=previous)
        self.serial, self.state = frame.serial, result.state
        pixels = images.to_uint8(result.image)
        jpeg = images.encode(pixels, "JPEG", frame.quality)
        seconds = time.perf_counter() - clock
        return WalkPainted(jpeg, *size, frame.serial, continued, seconds, pixels if keep_pixels else None)
