"""The painter port: the one way the service has a picture painted, whoever paints it.

Three operations: a walk frame (:meth:`Painter.walk_frame`), a render (:meth:`Painter.render`) and a film's
frames (:meth:`Painter.film`), with a walker's place (:meth:`Painter.admit`, :meth:`Painter.leave`). Two
implementations: :class:`LocalPainter`, on this machine's threads (the workshop), and Ray's
(``cluster/port.py``), which falls back on the local one while Ray backs off. The service picks one when it
opens (``state.py``); the walk, the REST route and the films call it and never ask where it paints.

Every operation blocks: call it on a painter's thread (``Workshop.run``, or a film's own thread).
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Iterator
from functools import partial
from typing import Protocol

import numpy as np

from ..camera.camera import Camera
from ..media.camerapath import CameraPath
from ..media.walkframe import WalkCanvas, WalkFrame, WalkPainted
from ..painting.loop import PaintState, Workspace
from ..painting.sequence import paint_results
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util import images
from .memory import GiveBack
from .workshop import Workshop

Stop = Callable[[], bool] | None


class PainterFailed(Exception):
    """The painter lost its workers mid-film: ``retry_s`` seconds until it may go on from the last frame kept,
    None when it would fail again."""

    def __init__(self, message: str, retry_s: float | None = None):
        super().__init__(message)
        self.retry_s = retry_s


class Painter(Protocol):
    def walk_frame(self, walker: object, frame: WalkFrame, should_stop: Stop = None) -> WalkPainted:
        """``walker``'s frame, painted from the state it keeps of frame ``frame.after`` (else from ``I_0``),
        encoded. :class:`~rcp_server.painting.loop.Abandoned` once ``should_stop`` says so."""
        ...

    def render(
        self, scene: Scene, camera: Camera, width: int, height: int, params: PaintParams, time: float, should_stop: Stop
    ) -> np.ndarray:
        """One painting, (height, width, 3) uint8."""
        ...

    def film(
        self,
        scene: Scene,
        path: CameraPath,
        width: int,
        height: int,
        params: PaintParams,
        temporal: int | None,
        start: int,
        previous: PaintState | None,
        should_stop: Stop,
    ) -> Iterator[tuple[np.ndarray, PaintState | None]]:
        """The frames of ``path`` from ``start`` on, each (height, width, 3) uint8 with the state a temporal film
        goes on from (None when the painter keeps it itself). A temporal film from ``start > 0`` without
        ``previous`` paints the frames before ``start`` again (not yielded). :class:`PainterFailed` when it
        loses its workers."""
        ...

    def admit(self, walker: object, params: PaintParams, scene: Scene) -> None:
        """A place for ``walker``, or :class:`~.refusal.Refusal` (503, with a time to try again)."""
        ...

    def leave(self, walker: object) -> None:
        """``walker`` has gone: what it held is given back."""
        ...

    def release(self, walker: object) -> None:
        """``walker`` takes less memory from now on (a smaller view): the buffers it no longer needs go back, its
        kept state stays."""
        ...

    def figures(self) -> dict:
        """What the painter reports in ``/api/health`` beside the workshop's figures (nothing, on threads)."""
        ...

    def close(self) -> None: ...


class LocalPainter:
    """The painter on this machine's threads: walk frames and renders on the workshop's shared tile pool, a
    film's frames on its background lane (they take the cores the others leave)."""

    def __init__(self, workshop: Workshop, give_back: GiveBack | None = None):
        self.workshop = workshop
        self.give_back = give_back  # a closed walk's memory, back to the system once its buffers are gone
        self._walkers: dict[object, tuple[WalkCanvas, Workspace]] = {}
        self._lock = threading.Lock()

    def walk_frame(self, walker: object, frame: WalkFrame, should_stop: Stop = None) -> WalkPainted:
        with self._lock:
            canvas, workspace = self._walkers.setdefault(walker, (WalkCanvas(), Workspace()))
        # the buffers every painting of this walk works in, frame after frame (one painting at a time)
        return canvas.paint(frame, partial(self.workshop.paint, should_stop=should_stop, workspace=workspace))

    def render(
        self, scene: Scene, camera: Camera, width: int, height: int, params: PaintParams, time: float, should_stop: Stop
    ) -> np.ndarray:
        painted = self.workshop.paint(scene, camera, width, height, params, time=time, should_stop=should_stop)
        return images.to_uint8(painted.image)

    def film(
        self,
        scene: Scene,
        path: CameraPath,
        width: int,
        height: int,
        params: PaintParams,
        temporal: int | None,
        start: int,
        previous: PaintState | None,
        should_stop: Stop,
    ) -> Iterator[tuple[np.ndarray, PaintState | None]]:
        def paint_frame(camera, scene_time: float, frame_params: PaintParams, before: PaintState | None):
            return self.workshop.paint(
                scene, camera, width, height, frame_params, should_stop=should_stop, background=True,
                time=scene_time, previous=before,
            )  # fmt: skip

        first = 0 if temporal and previous is None else start  # no state to go on from: painted again up to here
        results = paint_results(paint_frame, path.frames(first), params, temporal, first, previous)
        for result in itertools.islice(results, start - first, None):
            yield images.to_uint8(result.image), result.state if temporal else None

    def admit(self, walker: object, params: PaintParams, scene: Scene) -> None:
        """Every walker that said hello has its place here (``max_sessions`` counts them)."""

    def leave(self, walker: object) -> None:
        with self._lock:
            held = self._walkers.pop(walker, None)
        if held is not None:
            self._drop(held[1])

    def release(self, walker: object) -> None:
        with self._lock:
            held = self._walkers.get(walker)
            if held is not None:
                self._walkers[walker] = (held[0], Workspace())
        if held is not None:
            self._drop(held[1])

    def _drop(self, workspace: Workspace) -> None:
        """``workspace``'s buffers go once its last painting stops, and their memory back to the system."""
        workspace.close()
        if self.give_back is not None:
            self.give_back.after(workspace)

    def figures(self) -> dict:
        return {}

    def close(self) -> None:
        with self._lock:
            self._walkers.clear()
