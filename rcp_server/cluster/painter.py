"""Painting on Ray: the same frames and paintings as the threads of one machine, pixel for pixel, on many;
a film goes on through a lost worker, its frames painted again.

What a frame needs (camera, time, the settings of its paintings: two within a cross-fade of a path that keys its
painting, blended where they are painted) is a few hundred bytes; what comes back is the frame as uint8,
3 bytes a pixel, through the object store, in order, with a bounded number of frames in flight.

What the method allows decides how the work splits (``sequence.py`` has the per-frame/temporal rule):

* per frame: frames are independent, so they go round the actors;
* temporal, ray-traced: a pixel reads only its own previous value, so a band of rows runs through every
  iteration *and every frame* on one actor, keeping its own previous state: no exchange between bands;
* temporal, image method: its lookups reach the whole screen, so whole frames run in order on one actor;
* one large painting (a REST render): a band of rows per actor, through every iteration (the image
  method's on one actor).

The parts: joining Ray and backing off (``connection.py``), the actor (``actor.py``), the crew
(``crew.py``), and here a film with its repaints. Ray is the ``cluster`` extra: it is imported only once
asked to paint on Ray.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from ..camera.camera import Camera
from ..painting.sequence import Looks, Shot, frame_looks
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .actor import Held, HeldScenes
from .connection import (
    Backoff,
    ClusterError,
    Connection,
    PaintingFailed,
    Unanswered,
    check_address,
    connect,
)
from .crew import Crew, Lost, broken, cancel, paint_bands, split

__all__ = [
    "Backoff",
    "ClusterError",
    "PaintingFailed",
    "RayPainter",
    "Unanswered",
    "check_address",
    "connect",
]

log = logging.getLogger("rcp")

IN_FLIGHT_PER_ACTOR = 2  # frames (or bands) queued on each actor: one painting, one ready to start
REPAINTS = 8  # times one sequence replaces lost workers and repaints their frames before it fails


@dataclass
class _Frame:
    """A frame in flight: its index in the sequence, shot and paintings (``sequence.frame_looks``), and the refs
    of its painting (one, or a band's each) with the crew member that paints it (per frame)."""

    index: int
    shot: tuple[Camera, float]
    looks: Looks
    refs: list
    actor: int = -1


class RayPainter:
    """Paints on Ray actors (``threads`` CPUs each; as many actors as the cluster has CPUs for, or ``actors``):
    sequences (:meth:`images`) and single large paintings (:meth:`render`), of any scene, several at once.

    One crew of actors serves every scene (:class:`~.crew.Crew`). A worker that dies is restarted by Ray and its
    calls retried; one gone for good is replaced. Either way a sequence loses only that worker's frames, painted
    again: per frame, its frames in flight; temporal, its band, painted again from the last frame it still holds
    (from the first frame when it holds none). After a failure, Ray is not tried for a while (:class:`Backoff`):
    each painting asked meanwhile fails at once. ``address``: as :func:`connect`."""

    def __init__(self, address: str | None = None, threads: int = 1, actors: int | None = None, num_cpus=None):
        self.address = address
        self.threads = threads
        self.connection = Connection(address, num_cpus)
        self.scenes = HeldScenes()  # the object-store scene cache: the films' crew's and the walkers'
        self.crew = Crew(self.connection, threads, actors, self.scenes)

    @property
    def backoff(self) -> Backoff:
        return self.connection.backoff

    def start(self, timeout_s: float | None = None) -> None:
        """Join (or start) Ray now, rather than with the first painting (see :meth:`.Connection.start`)."""
        self.connection.start(timeout_s)

    def ready(self) -> bool:
        """Whether Ray may be tried now (not backing off after a failure)."""
        return self.connection.ready()

    def actors(self) -> list:
        """The crew, started on first use."""
        return self.crew.actors()

    def hold(self, scene: Scene) -> Held:
        """``scene`` in the object store, put there once."""
        return self.crew.hold(scene)

    def warm(self, scene: Scene) -> list:
        """The crew, each actor holding ``scene`` warm (its BVH built): for timing the start apart."""
        actors = self.crew.actors()
        held = self.crew.hold(scene)
        try:
            self.crew.get([actor.warm.remote(held) for actor in actors], None)
        except Lost as lost:
            raise ClusterError(str(lost)) from None
        return actors

    def render(
        self,
        scene: Scene,
        camera: Camera,
        width: int,
        height: int,
        params: PaintParams,
        time: float = 0.0,
        should_stop: Callable[[], bool] | None = None,
    ) -> np.ndarray:
        """One painting from ``I_0``, (height, width, 3) uint8: exactly ``painting.paint``'s. The ray-traced
        method splits it into a band of rows per actor; the image method's lookups reach the whole screen, so
        it paints on one actor. Raises :class:`ClusterError`, or :class:`~.paintstate.Abandoned` once
        ``should_stop`` says so."""
        self.connection.check()
        try:
            workers = split(self.crew.actors(), width, height, params, camera)
            refs = paint_bands(workers, self.crew.hold(scene), None, 0, (camera, time), ((params, 1.0),))
            try:
                return np.concatenate(self.crew.get(refs, should_stop), axis=0)
            except Lost as lost:  # a painting of its own: the caller asks again, on a new crew
                self.crew.drop()
                raise ClusterError(str(lost)) from None
        except ClusterError as exc:
            if not isinstance(exc, PaintingFailed):
                self.connection.backoff.failed(str(exc))
            raise

    def images(
        self,
        scene: Scene,
        shots: Iterable[Shot],
        width: int,
        height: int,
        params: PaintParams,
        temporal: int | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> Iterator[np.ndarray]:
        """The paintings of ``shots``, in order, each (height, width, 3) uint8: exactly the frames
        ``sequence.paint_sequence`` paints with threads. Per frame, frames go round the actors; temporal and
        ray-traced, each actor paints one band of rows through every frame; temporal with the image method,
        one actor paints whole frames. A lost worker's frames are painted again (see the class). Raises
        :class:`ClusterError`, or :class:`~.paintstate.Abandoned` once ``should_stop`` says so."""
        self.connection.check()
        try:
            yield from self._images(scene, shots, width, height, params, temporal, should_stop)
        except ClusterError as exc:
            if not isinstance(exc, PaintingFailed):  # Ray's failure: not tried again for a while
                self.connection.backoff.failed(str(exc))
            raise

    def _images(self, scene, shots, width, height, params, temporal, should_stop) -> Iterator[np.ndarray]:
        actors = self.crew.actors()
        held = self.crew.hold(scene)
        job = f"job-{next(self.crew.serial)}"
        shots = list(shots)
        if not shots:
            return
        workers = _bands(actors, width, height, shots, params) if temporal else []
        limit = IN_FLIGHT_PER_ACTOR * (1 if temporal else len(actors))
        pending: deque[_Frame] = deque()  # the frames in flight, in order
        history: list[tuple[tuple[Camera, float], Looks]] = []  # temporal: what a band painted again needs
        repaints = 0

        def submit(index: int, shot: Shot) -> _Frame:
            looks = frame_looks(shot, params, temporal, index)
            when = (shot.camera, shot.scene_time)
            if not temporal:
                k = index % len(actors)
                return _Frame(index, when, looks, [actors[k].frame.remote(held, when, width, height, looks)], k)
            history.append((when, looks))
            return _Frame(index, when, looks, paint_bands(workers, held, job, index, when, looks))

        def take() -> np.ndarray:
            nonlocal repaints
            while True:
                try:
                    parts = self.crew.get(pending[0].refs, should_stop)
                    break
                except Lost as lost:
                    repaints += 1
                    if repaints > REPAINTS:
                        self.crew.drop()
                        raise ClusterError(f"{lost} (painted again {REPAINTS} times)") from None
                    log.warning("%s: its frames are painted again", lost)
                    if temporal:
                        self._repaint_bands(workers, held, job, pending, history)
                    else:
                        self._repaint_frames(actors, held, width, height, pending)
            pending.popleft()
            return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=0)

        try:
            for index, shot in enumerate(shots):
                pending.append(submit(index, shot))
                if len(pending) >= limit:
                    yield take()
            while pending:
                yield take()
        finally:
            for frame in pending:  # abandoned or failed: what is still queued is not painted
                cancel(frame.refs)
            if temporal:
                for actor, _ in workers:
                    actor.forget.remote(job)

    def _repaint_frames(self, actors: list, held: Held, width: int, height: int, pending: deque[_Frame]) -> None:
        """Per frame: the frames in flight that failed, and those of a worker gone for good (to its replacement:
        ``actors`` is updated), go again; the others are left to arrive."""
        replaced = set()
        for k, actor in enumerate(actors):
            if self.crew.painted(actor, None, None) is None:
                actors[k] = self.crew.replace(actor)
                replaced.add(k)
        for frame in pending:
            if frame.actor in replaced or broken(frame.refs):
                frame.refs = [actors[frame.actor].frame.remote(held, frame.shot, width, height, frame.looks)]

    def _repaint_bands(self, workers: list, held: Held, job: str, pending: deque[_Frame], history: list) -> None:
        """Temporal: each band that was lost (its worker gone for good, restarted without its states, or a
        frame of it failed) is painted again from the last frame its worker still holds (from the first frame
        when it holds none; a worker gone for good is replaced: ``workers`` is updated), then every frame in
        flight; the other bands go on as they were."""
        first = pending[0].index
        for b, (actor, region) in enumerate(workers):
            holds = self.crew.painted(actor, job, region)
            if holds is None:
                actor = self.crew.replace(actor)
                workers[b] = (actor, region)
                holds = []
            elif not (0 < first and max(holds, default=-1) < first - 1) and not any(
                broken([frame.refs[b]]) for frame in pending
            ):
                continue  # it holds what it goes on from, and nothing of it failed
            start = next((k + 1 for k in reversed(holds) if k < first), 0)  # the frame to go on from
            for k in range(start, first):  # results not needed: they only bring the band's state up to date
                actor.band.remote(held, job, region, k, *history[k])
            for frame in pending:
                frame.refs[b] = actor.band.remote(held, job, region, frame.index, frame.shot, frame.looks)

    def close(self) -> None:
        """Stop the actors, and Ray itself if this painter started it."""
        if not self.connection.connected:
            return
        self.crew.close()
        self.connection.close()


def _bands(actors: list, width: int, height: int, shots: list, params: PaintParams) -> list:
    """Who paints which rows of a temporal film (:func:`~.crew.split`), for the whole film: whole frames on one
    actor if any of its paintings (``params``, or a keyed path's) uses the image method, whose lookups reach the
    whole screen."""
    paintings = [look for k, shot in enumerate(shots) for look, _ in frame_looks(shot, params, None, k)]
    whole = next((look for look in paintings if look.method != "raytrace"), params)
    return split(actors, width, height, whole, shots[0].camera)
