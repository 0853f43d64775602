"""The painter port on Ray (``service/painter.py`` has the port): walk frames on the walkers' actors
(:class:`~.remote.RemoteWalks`), large renders in bands and films on the crew (:class:`~.remote.RemoteRay`, Ray's
driver in a child process that the server outlives); the
server's own threads (the port's local implementation) paint whatever Ray cannot paint now: while it backs
off after a failure, a walker it has no room for, a render too small to be worth sending.
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Iterator

import numpy as np

from ..camera.camera import Camera
from ..media.camerapath import CameraPath
from ..media.walkframe import WalkFrame, WalkPainted
from ..painting.loop import PaintState
from ..scene.scene import Scene
from ..service.painter import LocalPainter, PainterFailed, Stop
from ..service.refusal import Refusal
from ..settings.params import PaintParams
from .admission import Full
from .connection import ClusterError, PaintingFailed
from .remote import RemoteRay, RemoteWalks

log = logging.getLogger("rcp")

RETRY_S = 30  # a render Ray failed is mended by its operator, in minutes rather than seconds


class RayPort:
    """Paints on ``cluster`` (renders of ``min_work`` rays or more, films) and ``walks`` (walk frames, when the
    server paints its walkers on Ray), else on ``local``."""

    def __init__(self, cluster: RemoteRay, local: LocalPainter, min_work: int, walks: RemoteWalks | None = None):
        self.cluster = cluster
        self.local = local
        self.min_work = min_work
        self.walks = walks

    def walk_frame(self, walker: object, frame: WalkFrame, should_stop: Stop = None) -> WalkPainted:
        walks = self.walks
        if walks is not None and self.cluster.ready():
            try:
                clock = time.perf_counter()
                painted = walks.paint(
                    walker, frame.scene, frame.camera, frame.width, frame.height, frame.params, frame.time,
                    frame.quality, frame.serial, frame.after, should_stop=should_stop,
                )  # fmt: skip
                seconds = painted.seconds or time.perf_counter() - clock  # its round trip, as the planner times it
                bands = tuple((band.y, band.rows, band.jpeg) for band in painted.bands)
                return WalkPainted(
                    painted.jpeg, painted.width, painted.height, frame.serial, painted.continued, seconds,
                    painted.pixels, bands,
                )  # fmt: skip
            except ClusterError as exc:  # painted here meanwhile; Ray's failure says so once, as it backs off
                log.debug("a walk frame painted on the server: %s", exc)
        return self.local.walk_frame(walker, frame, should_stop)

    def render(
        self, scene: Scene, camera: Camera, width: int, height: int, params: PaintParams, time: float, should_stop: Stop
    ) -> np.ndarray:
        work = width * height * params.spp * params.iterations
        if work >= self.min_work and self.cluster.ready():  # a large render: the cores here stay with the walks
            try:
                return self.cluster.render(scene, camera, width, height, params, time, should_stop)
            except PaintingFailed as exc:  # it would fail here too; said in one line, the operator's to mend
                raise Refusal(str(exc), 503, RETRY_S) from None
            except ClusterError as exc:  # Ray backs off now: painted here meanwhile
                log.error("a render on Ray failed, painted on the server: %s", exc)
        return self.local.render(scene, camera, width, height, params, time, should_stop)

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
        if not self.cluster.ready():  # Ray backs off: the film goes on here meanwhile
            yield from self.local.film(scene, path, width, height, params, temporal, start, previous, should_stop)
            return
        try:
            if temporal:  # the bands' states live on the actors: the frames before ``start`` are painted again
                paintings = self.cluster.images(scene, path.frames(), width, height, params, temporal, should_stop)
                paintings = itertools.islice(paintings, start, None)
            else:
                paintings = self.cluster.images(scene, path.frames(start), width, height, params, None, should_stop)
            for image in paintings:
                yield image, None
        except PaintingFailed as exc:  # it would fail again
            raise PainterFailed(str(exc)) from None
        except ClusterError as exc:  # Ray failed: it backs off, and the film goes on from its last frame
            raise PainterFailed(str(exc), self.cluster.backoff.wait_s()) from None

    def admit(self, walker: object, params: PaintParams, scene: Scene) -> None:
        if self.walks is None:
            return
        try:
            self.walks.admit(walker, params, scene)
        except Full as full:
            raise Refusal(str(full), 503, full.retry_after) from None

    def release(self, walker: object) -> None:
        self.local.release(walker)  # a walker on Ray holds its buffers there

    def leave(self, walker: object) -> None:
        if self.walks is not None:
            self.walks.leave(walker)
        self.local.leave(walker)

    def figures(self) -> dict:
        return {} if self.walks is None else {"walks": self.walks.figures()}

    def close(self) -> None:
        if self.walks is not None:
            self.walks.close()
        self.cluster.close()
        self.local.close()
