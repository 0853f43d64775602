"""Walk-throughs painted on Ray: one actor a walker, admitted while the cluster has room, moved when lost.

The server routes (messages in, frames out); a walker's frames are painted and encoded by its own actor
(:class:`~.walkactor.WalkPainter`), which keeps the scene and the temporal state: a frame sends the camera
and returns the JPEG. Each actor paints one frame at a time, so walkers share the cores as their processes
do, each at the pace of its own frames: none waits behind another's queue.

* Admission (:mod:`.admission`): a walker takes a share of a node's cores, from the declared target and the
  measured cost of a ray; past the cluster's room it is told so in one line, with a time to try again. The
  actors ask Ray for no CPU (a film's crew holds every core it finds, and walkers must still be placed):
  the shares are counted here, and the autoscaler is asked for the admitted walkers' cores and one more
  walker's (``request_resources``), so the cluster grows and shrinks with them.
* A lost actor (its worker or node gone, or a frame that does not come back in bounded time) is replaced on
  a node with room, and the frame painted again there at once: the walker sees a pause. Its temporal state
  went with it: the new actor starts the recursion again from ``I_0`` and keeps its own from there.
* Ray lost as a whole raises :class:`~.connection.ClusterError` and backs off (the films' :class:`Backoff`,
  shared): the session paints here meanwhile, and comes back to Ray once it may be tried again.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..camera.camera import Camera
from ..painting.loop import Abandoned
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .actor import Held, portable
from .admission import CostMeter, Full, Target, capacity, pick_node, share
from .connection import ClusterError, Connection, PaintingFailed, first_line, ray_module, worker_failure
from .walkactor import Painted, WalkPainter

log = logging.getLogger("rcp")

POLL_S = 0.05  # how often a wait for a frame checks whether it is still wanted
FIRST_FRAME_S = 60.0  # a new actor's first frame (its process started, the scene fetched, its BVH built)
FRAME_LEAST_S = 2.0  # a frame not back within this, or FRAME_TIMES its walker's recent frame time, is lost
FRAME_TIMES = 8.0
NODES_FRESH_S = 2.0  # the nodes and their cores are asked of Ray again after this long
HELD_SCENES = 8  # scenes kept in the object store for the walkers
SPARE_START_S = 20.0  # a spare taken before it is warm: its start may take this long
TRY_S = 30.0  # after a failure, a new actor must start within this for Ray to count as back
SMALL = 8  # pixels each way of the frames that measure a frame's fixed cost
CALIBRATION_FRAMES = 3  # frames of each size measured: the cheapest counts (the others met a busy core)


@dataclass
class Place:
    """One admitted walker: its share of ``node``'s cores and, once it painted, its actor."""

    share: float
    node: str
    actor: Any = None
    warming: Any = None  # the ref of its actor's start (and its scene's build), until the first frame waits for it
    recent_s: float | None = None  # a running mean of its frames' round trips
    first_s: float = FIRST_FRAME_S  # how long its actor's first frame may take (less for a spare, warm already)


class Walks:
    """The walkers on the Ray of ``connection``, each admitted for ``target`` (see the module)."""

    def __init__(self, connection: Connection, target: Target, retry_s: int, max_threads: int = 8):
        self.connection = connection
        self.target = target
        self.retry_s = retry_s
        self.max_threads = max_threads
        self.cost = CostMeter()
        self.places: dict[object, Place] = {}
        self.frames = 0  # painted on Ray
        self.worker_cpu_s = 0.0  # CPU seconds the workers spent on them
        self.moved = 0  # walkers whose actor was lost and replaced
        self._lock = threading.Lock()
        self._measuring = threading.Lock()
        self._asker: threading.Thread | None = None  # the thread that asks Ray for its nodes
        self._asking: threading.Thread | None = None  # the last thread that asked the autoscaler
        self._trier: threading.Thread | None = None  # the thread that tries Ray again after a failure
        self._trying = False  # Ray failed: the walkers are painted here until it answers again
        self._closed = False
        self._spare: tuple[Any, str, Any] | None = None  # an actor started ahead, its node, the ref of its start
        self._nodes: tuple[float, dict[str, float]] = (-math.inf, {})
        self._held: dict[int, tuple[Scene, Held]] = {}
        self._generation = -1
        self._remote: Any = None
        self._serial = itertools.count(1)  # names the scenes held

    # ---- admission ----

    def share(self, params: PaintParams) -> float:
        """Cores a walker with ``params`` takes at the target (the cost measured so far)."""
        if self.cost.ray_s is None:
            raise ClusterError("the cost of a frame on Ray is not measured yet")
        return share(self.target, params.spp, params.iterations, self.cost)

    def capacity(self, params: PaintParams) -> int:
        """Walkers with ``params`` the cluster holds at the target."""
        return capacity(self.cores(), self.share(params))

    def describe(self, params: PaintParams) -> str:
        """One line: the walkers with ``params`` the cluster holds, at what share, on which cores."""
        cores = self.cores()
        return (
            f"room for {self.capacity(params)} walkers at {self.target} ({self.share(params):.2f} cores each) on "
            f"{len(cores)} nodes of {sum(cores.values()):g} cores"
        )

    def figures(self) -> dict:
        """What the walks on Ray did so far: walkers placed, frames painted there, the CPU seconds the workers
        spent on them, walkers moved after a lost actor, whether Ray is in use now."""
        return {
            "walkers": len(self.places),
            "frames": self.frames,
            "worker_cpu_s": round(self.worker_cpu_s, 3),
            "moved": self.moved,
            "on_ray": self.connection.ready() and not self._trying,
        }

    def admit(self, key: object, params: PaintParams, scene: Scene | None = None) -> None:
        """A place for walker ``key`` (its frames painted with ``params``), on the node with the most cores
        left; :class:`~.admission.Full` when there is none. Its actor starts now, building ``scene``, while the
        walker is told it is ready. While Ray backs off, nothing is reserved: the walker is painted on the
        server, and placed when Ray is back (:meth:`paint`)."""
        if self._trying or not self.connection.ready() or self.connection.gone() or self.cost.ray_s is None:
            return
        walker = self.share(params)
        with self._lock:
            cores = self.cores()
            node = pick_node(cores, self._taken(), walker)
            if node is None:
                held = capacity(cores, walker)
                raise Full(
                    f"the cluster has room for {held} walkers at {self.target} ({walker:.2f} cores each, measured)"
                    f" and all are walking",
                    self.retry_s,
                )
            place = self.places[key] = Place(walker, node)
        if scene is not None and self._remote is not None:
            self._start(place, scene)
        self._autoscale()

    def leave(self, key: object) -> None:
        """Walker ``key`` has gone: its actor stops, its place is free."""
        with self._lock:
            place = self.places.pop(key, None)
        if place is not None and place.actor is not None and not self._trying:
            _kill(place.actor)
        self._autoscale()

    def cores(self) -> dict[str, float]:
        """The live nodes' cores, node id -> CPUs: asked of Ray once, then again every ``NODES_FRESH_S`` on a thread
        (on a Ray that died, the question waits for a minute: no frame and no hello waits for it)."""
        when, nodes = self._nodes
        if not nodes:
            self._ask_nodes()
        elif time.monotonic() - when > NODES_FRESH_S and not (self._asker and self._asker.is_alive()):
            self._asker = threading.Thread(target=self._ask_nodes, name="rcp-ray-nodes", daemon=True)
            self._asker.start()
        return self._nodes[1]

    def _ask_nodes(self) -> None:
        found = {n["NodeID"]: float(n["Resources"].get("CPU", 0.0)) for n in ray_module().nodes() if n["Alive"]}
        self._nodes = (time.monotonic(), {node: cpu for node, cpu in found.items() if cpu > 0})

    def _autoscale(self) -> None:
        """Ask the autoscaler for the admitted walkers' cores and one more walker's: it adds a node before the
        next walker finds none, and lets one go when walkers leave (no autoscaler: nothing happens)."""
        shares = [place.share for place in self.places.values()]
        bundles = [{"CPU": s} for s in shares + shares[-1:]]
        if self._trying or not ray_module().is_initialized():  # Ray is down (a call could wait, or start one)
            return
        if self._closed:
            return
        self._asking = threading.Thread(target=_request, args=(bundles,), name="rcp-ray-autoscale", daemon=True)
        self._asking.start()

    # ---- painting ----

    def calibrate(self, scene: Scene, params: PaintParams, size: tuple[int, int] | None = None) -> tuple[float, float]:
        """Measure what a frame costs on a worker (:class:`~.admission.CostMeter`), on an actor of its own: frames
        of ``scene`` with ``params`` at ``size`` (the target's) and at ``SMALL`` pixels (the fewest CPU seconds of
        ``CALIBRATION_FRAMES`` each, after one that builds the scene). Returns (CPU seconds a frame, a ray)."""
        self._joined()
        actor = self._remote.remote(1)
        ray = ray_module()
        try:
            held = self._hold(scene)
            ray.get(actor.warm.remote(held), timeout=FIRST_FRAME_S)

            def cpu_s(width: int, height: int) -> float:
                shot = (scene.camera, width, height, params, 0.0, 70)
                calls = [actor.frame.remote(held, *shot, k, None) for k in range(CALIBRATION_FRAMES)]
                return min(p.cpu_s for p in ray.get(calls, timeout=FIRST_FRAME_S))

            width, height = size or (self.target.width, self.target.height)
            small, large = cpu_s(SMALL, SMALL), cpu_s(width, height)
        except Exception as exc:
            raise ClusterError(f"the cost of a frame on Ray was not measured: {first_line(exc)}") from None
        finally:
            _kill(actor)
        per_pixel = params.spp * params.iterations
        rays = width * height * per_pixel - SMALL * SMALL * per_pixel
        ray_s = max(large - small, 0.0) / max(rays, 1)
        self.cost.calibrated(small - SMALL * SMALL * per_pixel * ray_s, ray_s)
        assert self.cost.frame_s is not None
        return self.cost.frame_s, ray_s

    def paint(
        self,
        key: object,
        scene: Scene,
        camera: Camera,
        width: int,
        height: int,
        params: PaintParams,
        scene_time: float,
        quality: int,
        serial: int,
        after: int | None,
        should_stop: Callable[[], bool] | None = None,
        keep_pixels: bool = False,
    ) -> Painted:
        """Walker ``key``'s frame ``serial`` (see :meth:`.WalkPainter.frame`), painted on its actor, placed now
        if it has none. Raises :class:`ClusterError` when it cannot be painted on Ray (backing off, Ray gone,
        no room): the caller paints it itself; :class:`~rcp_server.painting.loop.Abandoned` once
        ``should_stop`` says so."""
        self.connection.check()
        if self._trying:  # after a failure, Ray is tried on a thread of its own; painted here meanwhile
            self._try_again(scene)
            raise NoRoom("Ray is being tried again")
        try:
            self._joined()
            if self.cost.ray_s is None:  # not measured at start-up: this walker's scene measures it
                with self._measuring:
                    if self.cost.ray_s is None:
                        self.calibrate(scene, params)
            if key not in self.places:
                try:
                    self.admit(key, params)
                except Full as full:
                    raise NoRoom(str(full)) from None
            place = self.places.get(key)
            if place is None:
                raise NoRoom("the walker has no place on Ray yet")
            for _ in range(2):
                if place.actor is None:
                    self._start(place, scene)
                ref = place.actor.frame.remote(
                    self._hold(scene), camera, width, height, params, scene_time, quality, serial, after, keep_pixels
                )
                try:
                    if place.warming is not None:  # the actor's start and the scene's build are not the frame's
                        self._wait(place.warming, place, should_stop)
                        place.warming = None
                    clock = time.perf_counter()
                    painted = self._wait(ref, place, should_stop)
                    painted = dataclasses.replace(painted, seconds=time.perf_counter() - clock)
                except _ActorLost as lost:
                    if key not in self.places:
                        raise Abandoned from None  # it left meanwhile: its actor was stopped
                    log.warning("a walker's Ray worker was lost (%s): moved to another", lost)
                    _kill(place.actor)
                    place.actor, after = None, None
                    self.moved += 1
                    continue
                self._painted(painted, place, params)
                self.connection.backoff.succeeded()
                return painted
            raise ClusterError("a walker's Ray worker was lost twice in a row")
        except (Abandoned, NoRoom, PaintingFailed):
            raise
        except ClusterError as exc:
            self._failed(str(exc))
            raise
        except (Exception, SystemExit) as exc:  # Ray's own, many and long (a stopped runtime's call exits): Ray failed
            self._failed(f"Ray failed a walk frame: {first_line(exc)}")
            raise ClusterError(f"Ray failed a walk frame: {first_line(exc)}") from None

    def _painted(self, painted: Painted, place: Place, params: PaintParams) -> None:
        self.frames += 1
        self.worker_cpu_s += painted.cpu_s
        self.cost.measured(painted.cpu_s, painted.width * painted.height * params.spp * params.iterations)

    def _failed(self, reason: str) -> None:
        """Ray failed as a whole: not tried for a while (painted here meanwhile), then tried again off the frames'
        path (:meth:`_try_again`; if its runtime stopped, it is joined afresh then: :meth:`.Connection.gone`). The
        actors are forgotten: each walker gets a new one once Ray is back."""
        log.warning("walkers painted on the server until Ray answers again: %s", reason)
        self.connection.gone()
        self.connection.backoff.failed(reason)
        with self._lock:
            self._trying, self._spare = True, None
            for place in self.places.values():
                place.actor = place.warming = None

    def _wait(self, ref, place: Place, should_stop: Callable[[], bool] | None) -> Any:
        """``ref``'s value (a frame, or the actor's start); :class:`_ActorLost` when its actor died or it took
        too long."""
        ray = ray_module()
        clock = time.monotonic()
        limit = place.first_s if place.recent_s is None else max(FRAME_LEAST_S, FRAME_TIMES * place.recent_s)
        while not ray.wait([ref], timeout=POLL_S)[0]:
            if should_stop is not None and should_stop():
                raise Abandoned
            if time.monotonic() - clock > limit:
                raise _ActorLost(f"no frame within {limit:.1f} s")
            if self.connection.gone():
                raise ClusterError("Ray stopped mid-walk")
        try:
            value = ray.get(ref)
        except (ray.exceptions.RayActorError, ray.exceptions.ObjectLostError) as exc:
            raise _ActorLost(first_line(exc)) from None
        except ray.exceptions.RayTaskError as exc:
            raise PaintingFailed(f"a walk frame failed on Ray: {worker_failure(exc)}") from None
        seconds = time.monotonic() - clock
        place.recent_s = seconds if place.recent_s is None else 0.7 * place.recent_s + 0.3 * seconds
        return value

    def _start(self, place: Place, scene: Scene) -> None:
        """An actor for ``place``: the spare when there is one (started already, its kernels loaded), else a new
        one on its node if that is still there, else on the node with most room; it builds ``scene`` at once
        (``place.warming``), and a new spare starts."""
        cores = self.cores()
        if place.node not in cores:
            place.node = pick_node(cores, self._taken(but=place), place.share) or place.node
        spare, self._spare = self._spare, None
        if spare is not None and spare[1] in cores:
            place.actor, place.node, warm = spare
            # a spare that is warm answers at once (a dead Ray is found in seconds); one still starting may take
            # a process's start
            place.first_s = FRAME_LEAST_S if ray_module().wait([warm], timeout=0)[0] else SPARE_START_S
        else:
            place.first_s = FIRST_FRAME_S
            if spare is not None:
                _kill(spare[0])
            place.actor = self._actor(place.node, self._threads(place.share, cores.get(place.node, 1.0)))
        held = self._hold(scene)
        place.warming, place.recent_s = place.actor.warm.remote(held), None
        self._start_spare(held, place.share)

    def _start_spare(self, held: Held, walker: float) -> None:
        """A spare actor on the node with most room for a walker of ``walker`` cores, warm with ``held``: a lost
        actor's walker, or a new walker, takes it and paints at once, rather than after a process starts."""
        node = pick_node(self.cores(), self._taken(), walker)
        if node is not None:
            actor = self._actor(node, self._threads(walker, self.cores()[node]))
            self._spare = (actor, node, actor.warm.remote(held))

    def _actor(self, node: str, threads: int) -> Any:
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        strategy = NodeAffinitySchedulingStrategy(node, soft=True)  # soft: elsewhere if it is gone
        return self._remote.options(scheduling_strategy=strategy).remote(threads)

    def _threads(self, walker: float, cores: float) -> int:
        """A walker's actor paints with as many threads as its share of cores, within its node's."""
        return max(1, min(self.max_threads, math.ceil(walker), int(cores)))

    def _taken(self, but: Place | None = None) -> dict[str, float]:
        """The cores the walkers' shares take on each node (node -> cores), ``but``'s aside."""
        taken: dict[str, float] = {}
        for place in list(self.places.values()):
            if place is not but:
                taken[place.node] = taken.get(place.node, 0.0) + place.share
        return taken

    def _try_again(self, scene: Scene) -> None:
        """Try Ray again on a thread (one at a time), off every frame's path: join it again if its runtime
        stopped, then start an actor that builds ``scene`` within ``TRY_S``; it becomes the spare, and the walkers
        go back to Ray. Else Ray backs off again."""
        if self._trier is not None and self._trier.is_alive():
            return

        def attempt() -> None:
            actor = None
            try:
                if self.connection.gone() and self.connection.address in (None, "", "local"):
                    # Ray's processes die with the thread that starts them: a runtime of our own is not started here
                    raise ClusterError("the local Ray runtime stopped")
                self._joined()
                actor = self._remote.remote(1)  # asks nothing of Ray that waits (the nodes would, on a dead one)
                warm = actor.warm.remote(self._hold(scene))
                if not self._waited(warm, TRY_S):
                    raise ClusterError(f"a Ray worker did not start within {TRY_S:g} s")
                self._ask_nodes()
                node = next(iter(self.cores()), None)
                with self._lock:
                    self._spare, self._trying = (actor, node, warm) if node else None, False
                log.info("walkers on Ray again")
            except (Exception, SystemExit) as exc:  # Ray's own, many: still down
                if actor is not None:
                    _kill(actor)
                self.connection.backoff.failed(f"Ray is still down: {first_line(exc)}")

        self._trier = threading.Thread(target=attempt, name="rcp-ray-try", daemon=True)
        self._trier.start()

    def _waited(self, ref, seconds: float) -> bool:
        """Whether ``ref`` is ready within ``seconds``, asked in short turns (a closing server stops waiting)."""
        deadline = time.monotonic() + seconds
        while not self._closed and time.monotonic() < deadline:
            if ray_module().wait([ref], timeout=POLL_S)[0]:
                ray_module().get(ref)
                return True
        return False

    def _joined(self) -> None:
        """Ray joined (again, after it stopped): what an earlier join held is forgotten."""
        with self.connection.lock:
            self.connection.join()
            if self._generation != self.connection.generation:
                self._generation = self.connection.generation
                self._held.clear()
                self._nodes = (-math.inf, {})
                for place in self.places.values():
                    place.actor = None
                self._spare = None
                self._remote = ray_module().remote(num_cpus=0, max_restarts=0)(WalkPainter)

    def _hold(self, scene: Scene) -> Held:
        """``scene`` in the object store, put there once."""
        with self._lock:
            entry = self._held.get(id(scene))
            if entry is None or entry[0] is not scene:
                entry = self._held[id(scene)] = (
                    scene,
                    Held(f"walk-{next(self._serial)}", [ray_module().put(portable(scene))]),
                )
                while len(self._held) > HELD_SCENES:
                    self._held.pop(next(iter(self._held)))
            return entry[1]

    def close(self) -> None:
        """Stop every walker's actor."""
        self._closed = True
        for thread in (self._trier, self._asker, self._asking):  # no call of theirs may outlive Ray's shutdown
            if thread is not None:
                thread.join(1.0)
        with self._lock:
            places, self.places = list(self.places.values()), {}
            spare, self._spare = self._spare, None
        for actor in [place.actor for place in places] + ([spare[0]] if spare else []):
            if actor is not None and not self._trying:
                _kill(actor)


def _request(bundles: list[dict]) -> None:
    """Ask the autoscaler for ``bundles`` (on a thread: it waits for Ray's control store)."""
    try:
        from ray.autoscaler.sdk import request_resources

        request_resources(bundles=bundles)
    except Exception as exc:  # an old Ray, a client connection: the cluster keeps its size
        log.debug("walkers' resources not requested: %s", first_line(exc))


class NoRoom(ClusterError):
    """A walker Ray has no place for (yet): painted on the server; not a failure of Ray's."""


class _ActorLost(Exception):
    """A walker's actor died, or its frame did not come back in bounded time."""


def _kill(actor) -> None:
    ray = ray_module()
    if not ray.is_initialized():  # Ray stopped, and its actors with it (a call now would start a runtime)
        return
    try:
        ray.kill(actor)
    except Exception:  # gone already, or Ray with it: nothing left to stop
        pass
