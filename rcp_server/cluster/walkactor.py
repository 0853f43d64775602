"""The walk actor: one walk-through's painter on a Ray worker, holding its scene and its temporal state.

A walk-through on Ray is held by one actor. It keeps the scene warm (its BVH built once) and the last frame's
per-pixel state, so a frame sends only the camera, the size and the settings (a few hundred bytes) and
returns only the JPEG, encoded here on the worker. Temporal mode continues from the state kept here, but only
from the frame the walk-through showed last (``after``): a state that is not that one (a frame the session
threw away, an actor started afresh after a loss) starts the recursion again from ``I_0``, as the threads
do when they have no state.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..camera.camera import Camera
from ..media.walkframe import WalkCanvas, WalkFrame
from ..painting.loop import paint
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .actor import Held, WarmScenes

WALK_SCENES = 2  # scenes a walk actor keeps built: the one shown and the one just left


@dataclass(frozen=True)
class Painted:
    """One walk frame, painted and encoded.

    jpeg : the encoded frame; width, height : the painting's size in pixels (both eyes of a stereo pair);
    serial : the frame whose state the worker keeps (None: painted on the server, the state is the session's);
    continued : it went on from the last frame's state (temporal), rather than from ``I_0``; paint_s : wall
    seconds painting and encoding on the worker; cpu_s : CPU seconds the worker's process spent on it (every
    thread); pixels : (height, width, 3) uint8, the painting before encoding, when asked for (tests); seconds :
    the frame's time as the server saw it (its round trip on Ray), what the walk's planner times."""

    jpeg: bytes
    width: int
    height: int
    serial: int | None
    continued: bool
    paint_s: float
    cpu_s: float
    pixels: np.ndarray | None = None
    seconds: float = 0.0


class WalkPainter:
    """A Ray actor that paints one walk-through's frames (``threads`` threads)."""

    def __init__(self, threads: int):
        self.threads = threads
        self.scenes = WarmScenes(WALK_SCENES)
        self.canvas = WalkCanvas()  # the frame whose state is kept, and that state

    def _scene(self, held: Held) -> Scene:
        return self.scenes.get(held)

    def warm(self, held: Held) -> int:
        """Build ``held``'s scene now and paint a tiny frame of it (the compiled kernels load in this process),
        before the first frame waits for them; the process id."""
        scene = self._scene(held)
        paint(scene, scene.camera, 8, 8, PaintParams(iterations=2), threads=1)
        return os.getpid()

    def frame(
        self,
        held: Held,
        camera: Camera,
        width: int,
        height: int,
        params: PaintParams,
        scene_time: float,
        quality: int,
        serial: int,
        after: int | None,
        keep_pixels: bool = False,
    ) -> Painted:
        """Frame ``serial``: painted from the state of frame ``after`` when this actor keeps it (temporal), else
        from ``I_0``; encoded as JPEG at ``quality``. ``width x height``: the painting's size, both eyes."""
        cpu = time.process_time()
        shot = WalkFrame(self._scene(held), camera, width, height, params, scene_time, quality, serial, after)
        done = self.canvas.paint(shot, partial(paint, threads=self.threads), keep_pixels)
        return Painted(
            done.jpeg,
            width,
            height,
            serial,
            done.continued,
            done.seconds,
            time.process_time() - cpu,
            done.pixels,
        )

    def pid(self) -> int:
        return os.getpid()
