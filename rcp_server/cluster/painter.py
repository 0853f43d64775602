"""Painting on Ray: the same frames and paintings as the threads of one machine, pixel for pixel, on many.

Workers are Ray actors that hold the scenes they paint warm: a scene's arrays are put in the object store
once, and each actor builds its BVH itself (an Embree handle cannot travel). What a frame needs (camera,
time, settings) is a few hundred bytes; what comes back is the frame as uint8, 3 bytes a pixel, through
the object store, in order, with a bounded number of frames in flight.

What the method allows decides how the work splits (``sequence.py`` has the per-frame/temporal rule):

* per frame: frames are independent, so they go round the actors;
* temporal, ray-traced: a pixel reads only its own previous value, so a band of rows runs through every
  iteration *and every frame* on one actor, keeping its own previous state: no exchange between bands;
* temporal, image method: its lookups reach the whole screen, so whole frames run in order on one actor;
* one large painting (a REST render): a band of rows per actor, through every iteration (the image
  method's on one actor).

Ray is the ``cluster`` extra: this module imports it only once asked to paint on Ray.
"""

from __future__ import annotations

import itertools
import logging
import math
import os
import socket
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, fields
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from ..camera.camera import Camera, Region
from ..painting.loop import Abandoned, PaintState, paint
from ..painting.sequence import Shot, frame_params
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util import images

log = logging.getLogger("rcp")

CONNECT_TIMEOUT_S = 10.0
"""How long an address may take to answer at all before we say it does not (``ray.init`` itself retries a
silent address for minutes)."""
IN_FLIGHT_PER_ACTOR = 2  # frames (or bands) queued on each actor: one painting, one ready to start
WARM_SCENES = 4  # scenes each actor keeps built (and the driver keeps in the object store)
RESTARTS = 3  # times Ray restarts a dead worker and retries its calls before a job fails
STOP_POLL_S = 0.1  # how often a wait on Ray checks whether the painting is still wanted
JOIN_RETRY_S = 1.0  # joining at start-up: how often an address that does not answer yet is asked again
REPAINTS = 8  # times one sequence replaces lost workers and repaints their frames before it fails
KEPT_STATES = 4  # temporal states each band keeps (frames in flight and the one before): a frame can be asked again
PROBE_S = 30.0  # how long a worker may take to say how far it got before it counts as lost
BACKOFF_FIRST_S = 5.0  # after a Ray failure, Ray is not tried for this long; doubled at each failure in a row
BACKOFF_MOST_S = 300.0


class ClusterError(RuntimeError):
    """Ray cannot be used as asked (not installed, an address that does not answer, a worker lost); one line."""


@dataclass
class Backoff:
    """When to try Ray again after it failed: not for ``first_s``, doubled at each failure in a row up to
    ``most_s``; a success starts again from nothing. A policy of clocks and counters (``clock`` is a fake one in
    tests): the painter asks it, and fails at once while it says wait."""

    first_s: float = BACKOFF_FIRST_S
    most_s: float = BACKOFF_MOST_S
    clock: Callable[[], float] = time.monotonic
    failures: int = 0
    until: float = 0.0
    reason: str = ""

    def failed(self, reason: str) -> None:
        self.failures += 1
        self.until = self.clock() + min(self.most_s, self.first_s * 2 ** (self.failures - 1))
        self.reason = reason

    def succeeded(self) -> None:
        self.failures, self.until, self.reason = 0, 0.0, ""

    def wait_s(self) -> float:
        """Seconds before Ray may be tried again (0: now)."""
        return max(0.0, self.until - self.clock())


class PaintingFailed(ClusterError):
    """A painting raised on a worker: a fault of the painting, not of Ray (asking again would fail again)."""


class Unanswered(ClusterError):
    """Nothing answers at the address (yet: a head that is starting answers in a moment)."""


def _ray():
    try:
        import ray
    except ImportError:
        raise ClusterError("Ray is not installed: pip install 'rcp-server[cluster]'") from None
    return ray


def check_address(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Raises :class:`ClusterError` unless ``address`` (``host:port``, ``ray://host:port``) takes a TCP
    connection within ``timeout_s``: a bounded answer for an address that is wrong or down."""
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if not host or not port:
        raise ClusterError(f"Ray address {address!r} is not host:port or ray://host:port")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        reason = f"no answer within {timeout_s:g} s" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise Unanswered(f"Ray address {address} does not answer ({reason})") from None


def connect(address: str | None = None, num_cpus: int | None = None, **local_options) -> bool:
    """Join the Ray cluster at ``address`` (or ``RAY_ADDRESS``), else start a local Ray runtime on this machine
    (``num_cpus``, ``local_options`` for ``ray.init``). Returns whether this call started Ray (then the caller
    shuts it down). An address is checked first (:func:`check_address`); every fault is a :class:`ClusterError`."""
    ray = _ray()
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address in ("local", ""):
        address = None
    if address not in (None, "auto"):
        check_address(address)
    if ray.is_initialized():  # joined already (a test's runtime, an earlier job): it stays as it is
        return False
    options: dict[str, Any] = {"log_to_driver": False, "configure_logging": False}
    if address is None:
        options |= {"include_dashboard": False, "num_cpus": num_cpus, **local_options}
    try:
        ray.init(address=address, **options)
    except Exception as exc:  # Ray's own errors are many and long: the first line says enough
        raise ClusterError(f"cannot start Ray{f' at {address}' if address else ''}: {_first_line(exc)}") from None
    return True


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _worker_failure(exc) -> str:
    """What failed on a Ray worker, in one line: the worker's exception type and the first line of its message
    (a ``RayTaskError``'s own first line names only the remote call, ``ray::Painter.band()``)."""
    cause = getattr(exc, "cause", None)
    if not isinstance(cause, BaseException):
        return _first_line(exc)
    text = str(cause).strip()
    return f"{type(cause).__name__}: {text.splitlines()[0]}" if text else type(cause).__name__


# ---- the scene as it travels ----


def portable(scene: Scene) -> dict:
    """What a scene is, without what it caches (BVHs, locks): its public fields, as ``Scene(**fields)``."""
    return {f.name: getattr(scene, f.name) for f in fields(scene) if not f.name.startswith("_")}


@dataclass(frozen=True)
class Held:
    """A scene in the object store: ``key`` names it to the actors, ``ref`` (in a list, so that Ray hands it
    over unread) is fetched only by an actor that does not hold the scene warm yet."""

    key: str
    ref: list


class LostState(RuntimeError):
    """A temporal band's previous frame is gone: its actor died and Ray restarted it empty."""


class Painter:
    """One Ray actor's work: paints frames, or bands of rows, of the scenes it holds warm.

    Scenes are built here (BVH included) on first use and kept for the next call, the last ``WARM_SCENES``;
    ``previous`` keeps the last ``KEPT_STATES`` paintings of each temporal band this actor paints (by job and
    frame), so a band's recursion continues here, frame after frame, with nothing sent back and forth but the
    band's pixels, and a frame asked again (after another worker was lost) is painted again the same."""

    def __init__(self, threads: int):
        self.threads = threads
        self.scenes: OrderedDict[str, Scene] = OrderedDict()
        self.previous: dict[tuple[str | None, Region], dict[int, PaintState]] = {}

    def _scene(self, held: Held) -> Scene:
        scene = self.scenes.get(held.key)
        if scene is None:
            scene = Scene(**_ray().get(held.ref[0]))
            scene.geometry(0.0)
            self.scenes[held.key] = scene
            while len(self.scenes) > WARM_SCENES:
                self.scenes.popitem(last=False)
        self.scenes.move_to_end(held.key)
        return scene

    def warm(self, held: Held) -> bool:
        """Build ``held``'s scene now, before the first frame waits for it."""
        self._scene(held)
        return True

    def frame(self, held: Held, shot: tuple[Camera, float], width: int, height: int, params: PaintParams):
        """A whole frame from ``I_0``: (height, width, 3) uint8."""
        camera, time = shot
        result = paint(self._scene(held), camera, width, height, params, time=time, threads=self.threads)
        return images.to_uint8(result.image)

    def band(
        self,
        held: Held,
        job: str | None,
        region: Region,
        index: int,
        shot: tuple[Camera, float],
        params: PaintParams,
    ) -> np.ndarray:
        """The rows of ``region`` of frame ``index``: from ``I_0`` for frame 0, else continuing from this band's
        painting of ``job``'s frame ``index - 1`` (kept when ``job`` is given): (rows, width, 3) uint8."""
        camera, time = shot
        previous = None
        if index > 0:
            previous = self.previous.get((job, region), {}).get(index - 1)
            if previous is None:
                raise LostState(f"a Ray worker was lost mid-job, and with it a band's frame {index - 1}")
        result = paint(
            self._scene(held),
            camera,
            region.full_width,
            region.full_height,
            params,
            time=time,
            previous=previous,
            region=region,
            threads=self.threads,
        )
        if job is not None:
            states = self.previous.setdefault((job, region), {})
            states[index] = result.state
            for old in [k for k in states if k <= index - KEPT_STATES]:
                del states[old]
        return images.to_uint8(result.image)

    def painted(self, job: str, region: Region) -> list[int]:
        """The frames of ``job`` whose band ``region`` this actor holds, to go on from."""
        return sorted(self.previous.get((job, region), {}))

    def forget(self, job: str) -> None:
        self.previous = {key: states for key, states in self.previous.items() if key[0] != job}

    def pid(self) -> int:
        return os.getpid()


@dataclass
class _Frame:
    """A frame in flight: its index in the sequence, shot and settings, and the refs of its painting (one, or a
    band's each) with the crew member that paints it (per frame)."""

    index: int
    shot: tuple[Camera, float]
    params: PaintParams
    refs: list
    actor: int = -1


class _Lost(Exception):
    """A worker was lost (dead, or restarted without its temporal state): its frames are to be painted again."""


class RayPainter:
    """Paints on Ray actors (``threads`` CPUs each; as many actors as the cluster has CPUs for, or ``actors``):
    sequences (:meth:`images`) and single large paintings (:meth:`render`), of any scene, several at once.

    One crew of actors serves every scene (actors hold their CPUs: a crew per scene would wait forever for
    another's); each actor keeps the scenes it paints warm. A worker that dies is restarted by Ray and its
    calls retried (``RESTARTS`` times); one gone for good is replaced. Either way a sequence loses only that
    worker's frames, painted again: per frame, its frames in flight; temporal, its band, painted again from the
    last frame it still holds (from the first frame when it holds none). After a failure, Ray is not tried
    for a while (:class:`Backoff`): each painting asked meanwhile fails at once. ``address``: as :func:`connect`."""

    def __init__(self, address: str | None = None, threads: int = 1, actors: int | None = None, num_cpus=None):
        self.address = address
        self.threads = threads
        self.backoff = Backoff()
        self._wanted = actors
        self._num_cpus = num_cpus
        self._started = False
        self._connected = False
        self._actors: list = []
        self._remote: Any = None  # Ray's actor class of Painter, made with the crew (Ray ships no types)
        self._held: OrderedDict[int, tuple[Scene, Held]] = OrderedDict()
        self._lock = threading.Lock()
        self._serial = itertools.count(1)  # names the scenes held and the jobs

    def start(self, timeout_s: float | None = None) -> None:
        """Join (or start) Ray now, rather than with the first painting; raises :class:`ClusterError`. With
        ``timeout_s``, an address that does not answer is asked again every ``JOIN_RETRY_S`` (a head starting
        beside us answers in a moment) until then, and one that takes connections but never joins (not Ray's)
        is given up then."""
        if timeout_s is None:
            with self._lock:
                self._start()
            return
        # joined on a thread of its own, so that it can be given up; Ray then leaves SIGTERM to us (a server stops
        # gracefully on it) and says so in a warning that is no news: filtered out
        logging.getLogger("ray._private.worker").addFilter(_NoSigtermNote())
        deadline = time.monotonic() + timeout_s
        outcome: list[BaseException | None] = []
        unanswered: list[Unanswered] = []

        def join() -> None:
            while True:  # an address nobody answers at yet (a head pod starting beside us) is asked again
                failure = _failure(self.start)
                if not isinstance(failure, Unanswered) or time.monotonic() + JOIN_RETRY_S > deadline:
                    outcome.append(failure)
                    return
                unanswered[:] = [failure]
                time.sleep(JOIN_RETRY_S)

        joiner = threading.Thread(target=join, name="rcp-ray-join", daemon=True)
        joiner.start()
        joiner.join(max(0.0, deadline - time.monotonic()))
        if not outcome:
            if unanswered:
                raise unanswered[0]
            raise ClusterError(f"Ray at {self.address} was not joined within {timeout_s:g} s (RCP_RAY_JOIN_S)")
        if outcome[0] is not None:
            raise outcome[0]

    def _start(self) -> None:
        if not self._connected:
            self._started = connect(self.address, self._num_cpus)
            self._connected = True

    def ready(self) -> bool:
        """Whether Ray may be tried now (not backing off after a failure)."""
        return self.backoff.wait_s() == 0

    def _check(self) -> None:
        wait = self.backoff.wait_s()
        if wait > 0:
            raise ClusterError(f"{self.backoff.reason} (Ray is tried again in {math.ceil(wait)} s)")

    def actors(self) -> list:
        """The crew, started on first use."""
        with self._lock:
            self._start()
            if not self._actors:
                ray = _ray()
                count = self._wanted or max(1, int(ray.cluster_resources().get("CPU", 1) // self.threads))
                self._remote = ray.remote(num_cpus=self.threads, max_restarts=RESTARTS, max_task_retries=RESTARTS)(
                    Painter
                )
                self._actors = [self._remote.remote(self.threads) for _ in range(count)]
            return list(self._actors)

    def _replace(self, lost) -> Any:
        """A new crew member in place of ``lost`` (gone for good); the same one for every job that asks."""
        with self._lock:
            replacement = self._remote.remote(self.threads)
            self._actors = [replacement if actor == lost else actor for actor in self._actors]
        return replacement

    def hold(self, scene: Scene) -> Held:
        """``scene`` in the object store, put there once (the last ``WARM_SCENES`` scenes stay)."""
        with self._lock:
            entry = self._held.get(id(scene))
            if entry is None or entry[0] is not scene:
                held = Held(f"scene-{next(self._serial)}", [_ray().put(portable(scene))])
                entry = self._held[id(scene)] = (scene, held)
                while len(self._held) > WARM_SCENES:
                    self._held.popitem(last=False)
            self._held.move_to_end(id(scene))
            return entry[1]

    def warm(self, scene: Scene) -> list:
        """The crew, each actor holding ``scene`` warm (its BVH built): for timing the start apart."""
        actors = self.actors()
        held = self.hold(scene)
        try:
            self._get([actor.warm.remote(held) for actor in actors], None)
        except _Lost as lost:
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
        self._check()
        try:
            workers = _split(self.actors(), width, height, params, camera)
            refs = _paint_bands(workers, self.hold(scene), None, 0, (camera, time), params)
            try:
                return np.concatenate(self._get(refs, should_stop), axis=0)
            except _Lost as lost:  # a painting of its own: the caller asks again, on a new crew
                self._drop()
                raise ClusterError(str(lost)) from None
        except ClusterError as exc:
            if not isinstance(exc, PaintingFailed):
                self.backoff.failed(str(exc))
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
        self._check()
        try:
            yield from self._images(scene, shots, width, height, params, temporal, should_stop)
        except ClusterError as exc:
            if not isinstance(exc, PaintingFailed):  # Ray's failure: not tried again for a while
                self.backoff.failed(str(exc))
            raise

    def _images(self, scene, shots, width, height, params, temporal, should_stop) -> Iterator[np.ndarray]:
        actors = self.actors()
        held = self.hold(scene)
        job = f"job-{next(self._serial)}"
        shots = iter(shots)
        first = next(shots, None)
        if first is None:
            return
        shots = itertools.chain([first], shots)
        workers = _split(actors, width, height, params, first.camera) if temporal else []
        limit = IN_FLIGHT_PER_ACTOR * (1 if temporal else len(actors))
        pending: deque[_Frame] = deque()  # the frames in flight, in order
        history: list[tuple[tuple[Camera, float], PaintParams]] = []  # temporal: what a band painted again needs
        repaints = 0

        def submit(index: int, shot: Shot) -> _Frame:
            p = frame_params(params, temporal, index)
            when = (shot.camera, shot.scene_time)
            if not temporal:
                k = index % len(actors)
                return _Frame(index, when, p, [actors[k].frame.remote(held, when, width, height, p)], k)
            history.append((when, p))
            return _Frame(index, when, p, _paint_bands(workers, held, job, index, when, p))

        def take() -> np.ndarray:
            nonlocal repaints
            while True:
                try:
                    parts = self._get(pending[0].refs, should_stop)
                    break
                except _Lost as lost:
                    repaints += 1
                    if repaints > REPAINTS:
                        self._drop()
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
                _cancel(frame.refs)
            if temporal:
                for actor, _ in workers:
                    actor.forget.remote(job)

    def _repaint_frames(self, actors: list, held: Held, width: int, height: int, pending: deque[_Frame]) -> None:
        """Per frame: the frames in flight that failed, and those of a worker gone for good (to its replacement:
        ``actors`` is updated), go again; the others are left to arrive."""
        replaced = set()
        for k, actor in enumerate(actors):
            if self._painted(actor, None, None) is None:
                actors[k] = self._replace(actor)
                replaced.add(k)
        for frame in pending:
            if frame.actor in replaced or _broken(frame.refs):
                frame.refs = [actors[frame.actor].frame.remote(held, frame.shot, width, height, frame.params)]

    def _repaint_bands(self, workers: list, held: Held, job: str, pending: deque[_Frame], history: list) -> None:
        """Temporal: each band that was lost (its worker gone for good, restarted without its states, or a
        frame of it failed) is painted again from the last frame its worker still holds (from the first frame
        when it holds none; a worker gone for good is replaced: ``workers`` is updated), then every frame in
        flight; the other bands go on as they were."""
        first = pending[0].index
        for b, (actor, region) in enumerate(workers):
            holds = self._painted(actor, job, region)
            if holds is None:
                actor = self._replace(actor)
                workers[b] = (actor, region)
                holds = []
            elif not (0 < first and max(holds, default=-1) < first - 1) and not any(
                _broken([frame.refs[b]]) for frame in pending
            ):
                continue  # it holds what it goes on from, and nothing of it failed
            start = next((k + 1 for k in reversed(holds) if k < first), 0)  # the frame to go on from
            for k in range(start, first):  # results not needed: they only bring the band's state up to date
                actor.band.remote(held, job, region, k, *history[k])
            for frame in pending:
                frame.refs[b] = actor.band.remote(held, job, region, frame.index, frame.shot, frame.params)

    def _painted(self, actor, job: str | None, region: Region | None) -> list[int] | None:
        """The frames of ``job``'s band ``region`` that ``actor`` holds (any list when ``job`` is None), or None
        when the actor is gone for good (no answer within ``PROBE_S``)."""
        ray = _ray()
        try:
            if job is None:
                ray.get(actor.pid.remote(), timeout=PROBE_S)
                return []
            return ray.get(actor.painted.remote(job, region), timeout=PROBE_S)
        except (ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError):
            return None

    def _get(self, refs: list, should_stop: Callable[[], bool] | None) -> list:
        """The values of ``refs``, waiting in short turns so that ``should_stop`` is heard. A worker lost is
        :class:`_Lost`; any other fault of Ray's a :class:`ClusterError`."""
        ray = _ray()
        try:
            while True:  # asked before every wait, the first among them: frames quicker than STOP_POLL_S never
                # wait, and a job stopped (cancelled, or its server stopping) would paint on to its last frame
                if should_stop is not None and should_stop():
                    _cancel(refs)
                    raise Abandoned
                if not ray.wait(refs, num_returns=len(refs), timeout=STOP_POLL_S)[1]:
                    break
            values = ray.get(refs)
        except (ray.exceptions.RayActorError, ray.exceptions.ObjectLostError) as exc:
            raise _Lost(f"a Ray worker was lost mid-job: {_first_line(exc)}") from None
        except ray.exceptions.RayTaskError as exc:
            if isinstance(exc.cause, LostState):
                raise _Lost(str(exc.cause)) from None
            raise PaintingFailed(f"a painting failed on Ray: {_worker_failure(exc)}") from None
        self.backoff.succeeded()
        return values

    def _drop(self) -> None:
        """Forget a crew that lost an actor for good: the next painting starts a new one."""
        with self._lock:
            actors, self._actors = self._actors, []
        for actor in actors:
            _ray().kill(actor)

    def close(self) -> None:
        """Stop the actors, and Ray itself if this painter started it."""
        if not self._connected:
            return
        self._drop()
        self._held.clear()
        if self._started:
            _ray().shutdown()
        self._connected = False


class _NoSigtermNote(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "SIGTERM handler is not set" not in record.getMessage()


def _failure(call: Callable[[], Any]) -> BaseException | None:
    """What ``call()`` raised, None if nothing."""
    try:
        call()
    except BaseException as exc:  # handed to the thread that waits for it
        return exc
    return None


def _broken(refs: list) -> bool:
    """Whether any of ``refs`` has arrived as an error (one still on its way is not known to be)."""
    ray = _ray()
    ready, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
    for ref in ready:
        try:
            ray.get(ref, timeout=0)
        except Exception:
            return True
    return False


def _split(actors: list, width: int, height: int, params: PaintParams, camera: Camera) -> list[tuple[Any, Region]]:
    """Who paints which rows of a ``width x height`` painting: a band each (fewer bands when there are fewer
    rows than actors) for the ray-traced method, where a pixel reads only its own previous value; the whole
    image on the first actor for the image method, whose lookups reach the whole screen, and for eyes that share
    their smudges (the right eye reads the left's)."""
    if params.method != "raytrace" or (camera.eyes == "shared" and camera.stereo != "mono"):
        return [(actors[0], Region(width, height))]
    bands = Region(width, height).tiles(-(-height // len(actors)))
    return list(zip(actors, bands, strict=False))


def _paint_bands(
    workers: list[tuple[Any, Region]],
    held: Held,
    job: str | None,
    index: int,
    shot: tuple[Camera, float],
    params: PaintParams,
) -> list:
    """The refs of one frame's bands: each band paints exactly its crop of the painting."""
    return [actor.band.remote(held, job, band, index, shot, params) for actor, band in workers]


def _cancel(refs: list) -> None:
    for ref in refs:
        try:
            _ray().cancel(ref)
        except Exception:  # finished meanwhile, or its actor is gone: nothing left to stop
            pass
