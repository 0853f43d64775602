"""Walk-throughs painted on Ray: each walker admitted while the cluster has room, its frames painted in bands by a
crew of actors on distinct nodes, the crew shrunk when a node is lost.

The server routes (messages in, frames out); a walker's frame is painted and encoded by its crew
(:class:`~.walkactor.WalkPainter`), one actor a node, each painting and encoding its own band of rows and keeping
that band's temporal state: each pixel reads only its own previous values, so the bands need no halo and no
exchange, and a frame is one call per node. The bands come back as JPEGs of their own and travel to the client as
they are.

* Admission (:mod:`.admission`): a walker takes a share of the cores, from the declared target and the measured
  cost of a ray; never more walkers than the cluster's room (whole walkers per node). Its crew may be larger than
  its share: alone, a walker paints on every node (as many as help: :func:`~.admission.crew_size`); with others,
  the nodes are dealt out fairly (:func:`~.admission.crews`). The walk's planner sees the crew's quicker frames and
  sizes the next ones from them.
* A crew member lost (its worker or node gone, or a band that does not come back in bounded time) leaves the crew
  and the frame is painted again at once by the others; a new member starts on a live node off the frames' path
  and joins once it is warm. A walker with no warm member yet is painted on the server meanwhile (:class:`NoRoom`).
* Ray lost as a whole raises :class:`~.connection.ClusterError`: the caller paints on the server and backs off.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..camera.camera import Camera, Region
from ..painting.loop import Abandoned
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .actor import HeldScenes
from .admission import CostMeter, Full, Target, band_rows, capacity, crew_size, crews, pick_node, share
from .calibration import calibrate
from .connection import ClusterError, Connection, PaintingFailed, first_line
from .inventory import Inventory
from .pool import FIRST_FRAME_S, ActorLost, Member, Pool, kill, wait_all
from .spread import Spread
from .walkactor import Painted, joined, pack

log = logging.getLogger("rcp")

FRAME_LEAST_S = 2.0  # a band not back within this, or FRAME_TIMES its walker's recent frame time, is lost
FRAME_TIMES = 8.0
ATTEMPTS = 3  # a frame whose crew members are lost is painted again by the others this many times


@dataclass
class Place:
    """One admitted walker: its home node (where its share is counted), its crew (node -> member) and what its
    frames took: the round trip, the painting on one node (all bands' wall seconds), the overhead beyond it."""

    home: str
    order: int
    crew: dict[str, Member] = field(default_factory=dict)
    moving: dict[str, Member] = field(default_factory=dict)  # node -> a member warming in a new group, to take over
    spread: Spread = field(default_factory=Spread)
    frames: int = 0
    recent_s: float | None = None
    paint_s: float | None = None
    overhead_s: float | None = None

    def staffed(self, wanted: list[str], threads: dict[str, int], pool: Pool, held) -> list[Member]:
        """The crew on the ``wanted`` nodes (of those live, ``threads`` each), in the bundles of the walker's
        placement group over them (:mod:`.spread`, built off this path): members elsewhere or stale leave, new ones
        start once the group holds their node, and a member of an older group moves into the new one (it paints
        until its successor is warm); the warm ones paint, by node id (so a band keeps its rows frame after frame)."""
        live = [node for node in wanted if node in threads]
        self.spread.want(live)
        for crew in (self.crew, self.moving):
            for node in list(crew):
                if node not in live or crew[node].stale():
                    kill(crew.pop(node).actor)
        for node in live:
            self._seat(node, threads[node], pool, held)
        for node in [node for node, member in self.moving.items() if member.ready()]:
            old, self.crew[node] = self.crew.get(node), self.moving.pop(node)
            if old is not None:
                kill(old.actor)
        self.spread.release({m.group for m in [*self.crew.values(), *self.moving.values()]})
        return [self.crew[node] for node in sorted(self.crew) if self.crew[node].ready()]

    def _seat(self, node: str, threads: int, pool: Pool, held) -> None:
        """A member on ``node`` in its bundle of the ready group (by affinity when Ray has no such groups)."""
        member = self.crew.get(node)
        if self.spread.off:
            if member is None:
                self.crew[node] = pool.start(node, threads, held)
            return
        seat = self.spread.seat(node)
        if seat is None or (member is not None and member.group == seat.group_id) or node in self.moving:
            return  # no group holds the node yet (the members there paint meanwhile), or it is seated already
        if member is None:
            self.crew[node] = pool.start(node, threads, held, seat)
        elif not self.moving and self.spread.settled():  # one at a time, once the crew has settled
            self.moving[node] = pool.start(node, threads, held, seat)

    def lose(self, lost: ActorLost) -> list[str]:
        """The members ``lost`` leave the crew, stopped; the nodes they were on."""
        nodes = [node for node, member in self.crew.items() if member.actor in lost.actors]
        for node in nodes:
            kill(self.crew.pop(node).actor)
            if node in self.moving:
                kill(self.moving.pop(node).actor)
        return nodes

    def stop(self) -> None:
        """Its crew stops, and its placement groups are removed."""
        for member in [*self.crew.values(), *self.moving.values()]:
            kill(member.actor)
        self.spread.close()

    def forget(self) -> None:
        """Ray was joined again: its actors and groups went with the runtime before."""
        self.crew.clear()
        self.moving.clear()
        self.spread = Spread()

    def painted(self, painted: Painted, params: PaintParams, seconds: float, cost: CostMeter) -> None:
        """One frame painted in ``seconds``: its times folded into the walker's, its cost a ray into ``cost``."""
        self.frames += 1
        bands = painted.bands or ()
        paint_s = sum(b.paint_s for b in bands) if bands else painted.paint_s
        overhead = max(0.0, seconds - painted.paint_s)
        self.recent_s = seconds if self.recent_s is None else 0.7 * self.recent_s + 0.3 * seconds
        self.paint_s = paint_s if self.paint_s is None else 0.7 * self.paint_s + 0.3 * paint_s
        self.overhead_s = overhead if self.overhead_s is None else 0.7 * self.overhead_s + 0.3 * overhead
        rays = painted.width * painted.height * params.spp * params.iterations
        cost.measured(painted.cpu_s / max(1, len(bands)), rays // max(1, len(bands)))


class Walks:
    """The walkers on the Ray of ``connection``, each admitted for ``target`` (see the module); ``scenes``: the
    object-store scene cache shared with the films' crew."""

    def __init__(
        self,
        connection: Connection,
        target: Target,
        retry_s: int,
        scenes: HeldScenes | None = None,
        max_threads: int = 8,
    ):
        self.connection = connection
        self.target = target
        self.retry_s = retry_s
        self.max_threads = max_threads
        self.scenes = scenes or HeldScenes()
        self.cost = CostMeter()
        self.inventory = Inventory()
        self.pool = Pool()
        self.places: dict[object, Place] = {}
        self.frames = 0  # painted on Ray
        self.worker_cpu_s = 0.0  # CPU seconds the workers spent on them
        self.moved = 0  # crew members lost and left behind
        self._lock = threading.Lock()
        self._order = itertools.count()
        self._generation = -1

    # ---- admission ----

    def share(self, params: PaintParams) -> float:
        """Cores a walker with ``params`` takes at the target (the cost measured so far)."""
        if self.cost.ray_s is None:
            raise ClusterError("the cost of a frame on Ray is not measured yet")
        return share(self.target, params.spp, params.iterations, self.cost)

    def capacity(self, params: PaintParams) -> int:
        """Walkers with ``params`` the cluster holds at the target."""
        return capacity(self.inventory.cores(), self.share(params))

    def describe(self, params: PaintParams) -> str:
        """One line: the walkers with ``params`` the cluster holds, at what share, on which cores."""
        cores = self.inventory.cores()
        return (
            f"room for {self.capacity(params)} walkers at {self.target} ({self.share(params):.2f} cores each) on "
            f"{len(cores)} nodes of {sum(cores.values()):g} cores"
        )

    def figures(self) -> dict:
        """What the walks on Ray did so far: walkers placed, frames painted there, the CPU seconds the workers
        spent on them, crew members lost, and each walker's crew size and frames."""
        return {
            "walkers": len(self.places),
            "frames": self.frames,
            "worker_cpu_s": round(self.worker_cpu_s, 3),
            "moved": self.moved,
            "crews": [len(place.crew) for place in list(self.places.values())],
            "painted": [place.frames for place in list(self.places.values())],
        }

    def admit(self, key: object, params: PaintParams, scene: Scene | None = None) -> None:
        """A place for walker ``key`` (its frames painted with ``params``) on the node with the most room, never
        past the cluster's room counted at today's cost; :class:`~.admission.Full` when there is none. Its crew
        starts now, building ``scene``, while the walker is told it is ready."""
        self._joined()
        walker = self.share(params)
        with self._lock:
            if key in self.places:
                return
            cores = self.inventory.cores()
            held = capacity(cores, walker)
            homes = _homes(self.places, walker)
            node = pick_node(cores, homes, walker) if len(self.places) < held else None
            if node is None:
                raise Full(
                    f"the cluster has room for {held} walkers at {self.target} ({walker:.2f} cores each, measured)"
                    f" and all are walking",
                    self.retry_s,
                )
            self.places[key] = Place(node, next(self._order))
        if scene is not None:
            self._staff(key, self.scenes.hold(scene), scene.camera, params, self.target.height)
        self.inventory.autoscale([walker] * len(self.places))

    def leave(self, key: object) -> None:
        """Walker ``key`` has gone: its crew stops, its place is free."""
        with self._lock:
            place = self.places.pop(key, None)
        if place is not None:
            place.stop()

    # ---- painting ----

    def calibrate(self, scene: Scene, params: PaintParams, size: tuple[int, int] | None = None) -> tuple[float, float]:
        """Measure what a frame costs on a worker (:func:`~.calibration.calibrate`) at ``size`` (the target's).
        Returns (CPU seconds a frame, a ray)."""
        self._joined()
        width, height = size or (self.target.width, self.target.height)
        return calibrate(self.pool, self.scenes.hold(scene), self.cost, scene.camera, params, width, height)

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
        """Walker ``key``'s frame ``serial`` (the painting's ``width x height``, both eyes), in bands over its
        crew. Raises :class:`NoRoom` when the walker has no place or no warm crew member yet (the caller paints it
        itself), :class:`ClusterError` when Ray failed, :class:`~rcp_server.painting.loop.Abandoned` once
        ``should_stop`` says so."""
        try:
            self._joined()
            place = self.places.get(key)
            if place is None:
                raise NoRoom("the walker has no place on Ray")
            held = self.scenes.hold(scene)
            for _ in range(ATTEMPTS):
                members = self._staff(key, held, camera, params, height)
                if not members:
                    raise NoRoom("the walker's crew is starting")
                regions = _bands(width, height, len(members), camera, params)
                clock = time.perf_counter()
                frame = (params, scene_time, quality, serial, after, keep_pixels)
                seated = zip(members, regions, strict=False)  # one region when the frame does not split
                refs = [_band(m, held, pack(held.key, camera, r, *frame)) for m, r in seated]
                limit = FIRST_FRAME_S if place.recent_s is None else max(FRAME_LEAST_S, FRAME_TIMES * place.recent_s)
                try:
                    bands = wait_all(refs, [m.actor for m in members], limit, should_stop, self.connection.gone)
                except ActorLost as lost:
                    if key not in self.places:
                        raise Abandoned from None  # it left meanwhile: its crew was stopped
                    self._lost(place, lost)
                    after = None
                    continue
                seconds = time.perf_counter() - clock
                painted = joined(bands, width, height, serial, seconds)
                self.frames += 1
                self.worker_cpu_s += painted.cpu_s
                place.painted(painted, params, seconds, self.cost)
                self.connection.backoff.succeeded()
                return painted
            raise ClusterError(f"a walker's Ray workers were lost {ATTEMPTS} times in a row")
        except (Abandoned, NoRoom, PaintingFailed, ClusterError):
            raise
        except (Exception, SystemExit) as exc:  # Ray's own, many and long (a stopped runtime's call exits): Ray failed
            raise ClusterError(f"Ray failed a walk frame: {first_line(exc)}") from None

    def _staff(self, key: object, held, camera: Camera, params: PaintParams, height: int) -> list[Member]:
        """Walker ``key``'s crew for its next frame: members start on the nodes it is dealt (:func:`crews`, as many
        as help: :func:`crew_size`) and leave the nodes it is not; the warm ones on its nodes paint (by node id,
        so a band keeps its rows frame after frame)."""
        cores = self.inventory.cores()
        with self._lock:
            place = self.places.get(key)
            if place is None:
                return []
            dealt, sharing = _dealt(self.places, cores)
        splits = _splits(camera, params)
        # the nodes with members first: a crew that shrinks keeps those it has rather than starting others
        wanted = sorted(dealt.get(key, [place.home]), key=lambda node: node not in place.crew)
        count = crew_size(len(wanted), height, place.paint_s, place.overhead_s) if splits else 1
        threads = {node: max(1, min(self.max_threads, int(cores[node] // sharing.get(node, 1)))) for node in cores}
        return place.staffed(wanted[:count], threads, self.pool, held)

    def _lost(self, place: Place, lost: ActorLost) -> None:
        """Crew members lost: they leave the crew (their nodes count as gone until Ray says otherwise)."""
        log.warning("a walker's Ray worker was lost (%s): its frame is painted again by the others", lost)
        for node in place.lose(lost):
            if lost.died:
                self.inventory.lost(node)
            self.moved += 1

    def _joined(self) -> None:
        """Ray joined (again, after it stopped): what an earlier join held is forgotten."""
        with self.connection.lock:
            self.connection.join()
            if self._generation != self.connection.generation:
                self._generation = self.connection.generation
                self.scenes.clear()
                self.inventory.forget()
                for place in self.places.values():
                    place.forget()
                self.pool.joined()

    def close(self) -> None:
        """Stop every walker's crew."""
        self.inventory.close()
        with self._lock:
            places, self.places = list(self.places.values()), {}
        for place in places:
            place.stop()


def _band(member: Member, held, frame: bytes):
    """The ref of a band call: the scene goes along only when the member's last scene was another."""
    if member.scene == held.key:
        return member.actor.packed.remote(frame)
    member.scene = held.key
    return member.actor.packed.remote(frame, held)


def _homes(places: dict[object, Place], walker: float) -> dict[str, float]:
    """The cores the walkers take on each home node, ``walker`` each."""
    homes: dict[str, float] = {}
    for place in places.values():
        homes[place.home] = homes.get(place.home, 0.0) + walker
    return homes


def _dealt(places: dict[object, Place], cores: dict[str, float]) -> tuple[dict[object, list[str]], dict[str, int]]:
    """The nodes each walker is dealt (:func:`~.admission.crews`, in the order they came), and how many walkers
    share each node."""
    order = sorted(places.items(), key=lambda item: item[1].order)
    dealt = crews(list(cores), [(k, p.home) for k, p in order])
    sharing: dict[str, int] = {}
    for nodes in dealt.values():
        for node in nodes:
            sharing[node] = sharing.get(node, 0) + 1
    return dealt, sharing


def _splits(camera: Camera, params: PaintParams) -> bool:
    """Whether a frame may be painted in bands: the ray-traced method, each pixel reading only its own previous
    values; not the image method (its lookups reach the whole screen), nor eyes that share their smudges."""
    return params.method == "raytrace" and not (camera.eyes == "shared" and camera.stereo != "mono")


def _bands(width: int, height: int, count: int, camera: Camera, params: PaintParams) -> list[Region]:
    count = count if _splits(camera, params) else 1
    return [Region(width, height, 0, y, width, rows) for y, rows in band_rows(height, count)]


class NoRoom(ClusterError):
    """A walker Ray has no place for (yet): painted on the server; not a failure of Ray's."""
