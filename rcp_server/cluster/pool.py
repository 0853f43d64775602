"""The walkers' actor pool: a walk actor started on a node and warmed with a scene, waited on in short turns, and
stopped; a lost one is told apart from a failed painting."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..painting.loop import Abandoned
from .actor import Held
from .connection import ClusterError, PaintingFailed, first_line, ray_module, worker_failure
from .spread import BUNDLE_MEMORY, Seat
from .walkactor import WalkPainter

POLL_S = 0.05  # how often a wait for a frame checks whether it is still wanted
FIRST_FRAME_S = 60.0  # a new actor's start (its process started, the scene fetched, its BVH built)


class ActorLost(Exception):
    """A walk actor died, or its frame did not come back in bounded time; ``actors`` are the ones lost."""

    def __init__(self, reason: str, actors: list, died: bool = True):
        super().__init__(reason)
        self.actors = actors
        self.died = died  # died (its node may be gone), rather than late (a busy machine)


@dataclass
class Member:
    """One crew member of a walker: its actor on ``node``, and the ref of its start (its scene built)."""

    node: str
    actor: Any
    warm: Any
    threads: int
    started: float
    group: str = ""  # the placement group it lives in (its walker's: :mod:`.spread`), none when placed by affinity
    scene: str = ""  # the key of the last scene it was sent (it keeps that one built)

    warmed: bool = False

    def ready(self) -> bool:
        """Whether its start finished (well or not: a failed one shows at its first frame); once it has, Ray is not
        asked again (a call into Ray's core worker a member a frame)."""
        if not self.warmed:
            self.warmed = bool(ray_module().wait([self.warm], timeout=0)[0])
        return self.warmed

    def stale(self) -> bool:
        """Whether it is still starting after ``FIRST_FRAME_S`` (its node gone, or never placed)."""
        return time.monotonic() - self.started > FIRST_FRAME_S and not self.ready()


class Pool:
    """Walk actors on the Ray joined: made with :meth:`joined` after each join (Ray ships no types)."""

    def __init__(self) -> None:
        self._remote: Any = None

    def joined(self) -> None:
        self._remote = ray_module().remote(num_cpus=0, max_restarts=0)(WalkPainter)

    def start(self, node: str, threads: int, held: Held, seat: Seat | None = None) -> Member:
        """A walk actor on ``node``, building ``held``'s scene at once: in its bundle ``seat`` of the walker's
        placement group (on ``node``), else held to ``node`` by affinity."""
        if seat is not None:
            options: dict[str, Any] = {"scheduling_strategy": seat.strategy(), "memory": BUNDLE_MEMORY}
        else:
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            # hard: a crew's bands are on distinct nodes or nowhere (an actor whose node went fails, and leaves it)
            options = {"scheduling_strategy": NodeAffinitySchedulingStrategy(node, soft=False)}
        actor = self._remote.options(**options).remote(threads)
        group = seat.group_id if seat is not None else ""
        return Member(node, actor, actor.warm.remote(held), threads, time.monotonic(), group, held.key)

    def started(self, held: Held) -> Any:
        """An actor anywhere, and the ref of its start: whether Ray answers at all."""
        actor = self._remote.remote(1)
        return actor, actor.warm.remote(held)


def wait_all(
    refs: list, actors: list, limit_s: float, should_stop: Callable[[], bool] | None, gone: Callable[[], bool]
) -> list:
    """The values of ``refs`` (each painted by the actor beside it in ``actors``). :class:`ActorLost` names the
    actors that died or did not answer within ``limit_s``; :class:`Abandoned` once ``should_stop`` says so."""
    ray = ray_module()
    clock = time.monotonic()
    while True:
        ready, waiting = ray.wait(refs, num_returns=len(refs), timeout=POLL_S)
        if not waiting:
            break
        lost = [actor for ref, actor in zip(refs, actors, strict=True) if ref in ready and _lost(ref)]
        if lost:
            raise ActorLost("a walker's Ray worker died", lost)
        if should_stop is not None and should_stop():
            raise Abandoned
        if time.monotonic() - clock > limit_s:
            late = [actor for ref, actor in zip(refs, actors, strict=True) if ref in waiting]
            raise ActorLost(f"no band within {limit_s:.1f} s", late, died=False)
        if gone():
            raise ClusterError("Ray stopped mid-walk")
    try:
        return ray.get(refs)  # all in: one get (a worker that died shows here, and is told apart below)
    except (ray.exceptions.RayActorError, ray.exceptions.ObjectLostError):
        lost = [actor for ref, actor in zip(refs, actors, strict=True) if _lost(ref)]
        raise ActorLost("a walker's Ray worker died", lost) from None
    except ray.exceptions.RayTaskError as exc:
        raise PaintingFailed(f"a walk frame failed on Ray: {worker_failure(exc)}") from None


def _lost(ref) -> bool:
    ray = ray_module()
    try:
        ray.get(ref, timeout=0)
    except (ray.exceptions.RayActorError, ray.exceptions.ObjectLostError):
        return True
    except Exception:  # a painting's own failure: said by the get that follows
        return False
    return False


def kill(actor) -> None:
    ray = ray_module()
    if not ray.is_initialized():  # Ray stopped, and its actors with it (a call now would start a runtime)
        return
    try:
        ray.kill(actor)
    except Exception:  # gone already, or Ray with it: nothing left to stop
        pass


def lost_reason(exc: BaseException) -> str:
    return first_line(exc)
