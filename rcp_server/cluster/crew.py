"""The crew: the Ray actors that paint films and large paintings, started on first use, a member replaced when it
is gone for good; the scenes they hold; who paints which rows; and waiting for what they paint.

One crew of actors serves every scene (actors hold their CPUs: a crew per scene would wait forever for
another's); each actor keeps the scenes it paints warm.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

from ..camera.camera import Camera, Region
from ..painting.loop import Abandoned
from ..painting.sequence import Looks
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .actor import Held, HeldScenes, LostState, Painter
from .connection import Connection, PaintingFailed, first_line, ray_module, worker_failure

RESTARTS = 3  # times Ray restarts a dead worker and retries its calls before a job fails
STOP_POLL_S = 0.1  # how often a wait on Ray checks whether the painting is still wanted
PROBE_S = 30.0  # how long a worker may take to say how far it got before it counts as lost


class Lost(Exception):
    """A worker was lost (dead, or restarted without its temporal state): its frames are to be painted again."""


class Crew:
    """Painter actors (``threads`` CPUs each; as many as the cluster has CPUs for, or ``actors``) on the Ray of
    ``connection``. A worker that dies is restarted by Ray and its calls retried (``RESTARTS`` times); one gone
    for good is replaced (:meth:`replace`)."""

    def __init__(
        self, connection: Connection, threads: int = 1, actors: int | None = None, scenes: HeldScenes | None = None
    ):
        self.connection = connection
        self.scenes = scenes or HeldScenes()  # the object-store scene cache, shared with the walkers
        self.threads = threads
        self._wanted = actors
        self._actors: list = []
        self._remote: Any = None  # Ray's actor class of Painter, made with the crew (Ray ships no types)
        self.serial = itertools.count(1)  # names the jobs
        self._generation = 0  # the connection's join the actors and scenes held belong to

    def actors(self) -> list:
        """The crew, started on first use."""
        with self.connection.lock:
            self.connection.join()
            if self._generation != self.connection.generation:  # Ray was joined again: what it held is gone
                self._actors, self._generation = [], self.connection.generation
                self.scenes.clear()
            if not self._actors:
                ray = ray_module()
                count = self._wanted or max(1, int(ray.cluster_resources().get("CPU", 1) // self.threads))
                self._remote = ray.remote(num_cpus=self.threads, max_restarts=RESTARTS, max_task_retries=RESTARTS)(
                    Painter
                )
                self._actors = [self._remote.remote(self.threads) for _ in range(count)]
            return list(self._actors)

    def replace(self, lost) -> Any:
        """A new crew member in place of ``lost`` (gone for good); the same one for every job that asks."""
        with self.connection.lock:
            replacement = self._remote.remote(self.threads)
            self._actors = [replacement if actor == lost else actor for actor in self._actors]
        return replacement

    def hold(self, scene: Scene) -> Held:
        """``scene`` in the object store, put there once (the last ``WARM_SCENES`` scenes stay)."""
        return self.scenes.hold(scene)

    def painted(self, actor, job: str | None, region: Region | None) -> list[int] | None:
        """The frames of ``job``'s band ``region`` that ``actor`` holds (any list when ``job`` is None), or None
        when the actor is gone for good (no answer within ``PROBE_S``)."""
        ray = ray_module()
        try:
            if job is None:
                ray.get(actor.pid.remote(), timeout=PROBE_S)
                return []
            return ray.get(actor.painted.remote(job, region), timeout=PROBE_S)
        except (ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError):
            return None

    def get(self, refs: list, should_stop: Callable[[], bool] | None) -> list:
        """The values of ``refs``, waiting in short turns so that ``should_stop`` is heard. A worker lost is
        :class:`Lost`; any other fault of Ray's a :class:`ClusterError`."""
        ray = ray_module()
        try:
            while True:  # asked before every wait, the first among them: frames quicker than STOP_POLL_S never
                # wait, and a job stopped (cancelled, or its server stopping) would paint on to its last frame
                if should_stop is not None and should_stop():
                    cancel(refs)
                    raise Abandoned
                if not ray.wait(refs, num_returns=len(refs), timeout=STOP_POLL_S)[1]:
                    break
            values = ray.get(refs)
        except (ray.exceptions.RayActorError, ray.exceptions.ObjectLostError) as exc:
            raise Lost(f"a Ray worker was lost mid-job: {first_line(exc)}") from None
        except ray.exceptions.RayTaskError as exc:
            if isinstance(exc.cause, LostState):
                raise Lost(str(exc.cause)) from None
            raise PaintingFailed(f"a painting failed on Ray: {worker_failure(exc)}") from None
        self.connection.backoff.succeeded()
        return values

    def drop(self) -> None:
        """Forget a crew that lost an actor for good: the next painting starts a new one."""
        with self.connection.lock:
            actors, self._actors = self._actors, []
        for actor in actors:
            ray_module().kill(actor)

    def close(self) -> None:
        """Stop the actors and forget the scenes held."""
        self.drop()
        self.scenes.clear()


def broken(refs: list) -> bool:
    """Whether any of ``refs`` has arrived as an error (one still on its way is not known to be)."""
    ray = ray_module()
    ready, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
    for ref in ready:
        try:
            ray.get(ref, timeout=0)
        except Exception:
            return True
    return False


def split(actors: list, width: int, height: int, params: PaintParams, camera: Camera) -> list[tuple[Any, Region]]:
    """Who paints which rows of a ``width x height`` painting: a band each (fewer bands when there are fewer
    rows than actors) for the ray-traced method, where a pixel reads only its own previous value; the whole
    image on the first actor for the image method, whose lookups reach the whole screen, and for eyes that share
    their smudges (the right eye reads the left's)."""
    if params.method != "raytrace" or (camera.eyes == "shared" and camera.stereo != "mono"):
        return [(actors[0], Region(width, height))]
    bands = Region(width, height).tiles(-(-height // len(actors)))
    return list(zip(actors, bands, strict=False))


def paint_bands(
    workers: list[tuple[Any, Region]],
    held: Held,
    job: str | None,
    index: int,
    shot: tuple[Camera, float],
    looks: Looks,
) -> list:
    """The refs of one frame's bands, painted with its ``looks`` (``sequence.frame_looks``): each band paints
    exactly its crop of the painting."""
    return [actor.band.remote(held, job, band, index, shot, looks) for actor, band in workers]


def cancel(refs: list) -> None:
    for ref in refs:
        try:
            ray_module().cancel(ref)
        except Exception:  # finished meanwhile, or its actor is gone: nothing left to stop
            pass
