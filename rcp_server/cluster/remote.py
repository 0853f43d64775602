"""The server's side of Ray: Ray's driver in a child process (:mod:`.driver`), called over a socket, restarted off
the frames' path after it died; and the walkers admitted on Ray or, past its room, on the server's own cores.

The serving process never imports Ray's runtime into itself: ``ray stop --force``, a killed raylet or GCS, a lost
head end at most the child. Every call in flight then fails at once with a :class:`~.connection.ClusterError`
(the session, the REST route and the films paint here meanwhile), Ray backs off (:class:`~.connection.Backoff`),
and once its wait is over a new driver is started on a thread: when it has joined, the walks go back to Ray.
"""

from __future__ import annotations

import itertools
import json
import logging
import math
import socket
import subprocess
import sys
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from multiprocessing.connection import Connection as Pipe
from typing import Any

import numpy as np

from ..camera.camera import Camera
from ..painting.loop import Abandoned
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .actor import portable
from .admission import Full, Target
from .connection import JOIN_RETRY_S, Backoff, ClusterError, PaintingFailed, Unanswered, check_address, first_line
from .driver import SCENES, SceneKey
from .walkactor import Painted
from .walks import NoRoom

log = logging.getLogger("rcp")

POLL_S = 0.05  # how often a call waiting for its answer checks whether it is still wanted
JOIN_S = 60.0  # a restarted driver must have joined Ray within this
LOCAL_TRY_S = 2.0  # a walker painted here asks for a place on Ray again at most this often
ERRORS: dict[str, type[Exception]] = {
    "NoRoom": NoRoom,
    "PaintingFailed": PaintingFailed,
    "ClusterError": ClusterError,
    "ValueError": ValueError,
}


class _Down(ClusterError):
    """The driver is not running (yet, or any more)."""


class DriverProcess:
    """The life of Ray's driver in a child process, at ``address`` (as :func:`~.connection.connect`: ``local``
    starts a runtime of the child's own): started, its answers read, started again off the frames' path after it
    died, stopped; ``target`` and ``retry_s``: the walkers' (None: no walkers on Ray)."""

    def __init__(self, address: str | None, target: Target | None = None, retry_s: int = 30):
        self.address = address
        self.target = target
        self.retry_s = retry_s
        self.backoff = Backoff()
        self.generation = 0  # counts the drivers started: scenes are sent to each once
        self.pid: int | None = None
        self._pipe: Pipe | None = None
        self._process: subprocess.Popen | None = None
        self._pending: dict[int, Future] = {}
        self._calls = itertools.count(1)
        self._sending = threading.Lock()
        self._lock = threading.Lock()
        self._sent: dict[int, int] = {}  # scene key -> the generation it was sent to
        self._keys: OrderedDict[int, tuple[Scene, int]] = OrderedDict()  # the scenes named to drivers
        self._serial = itertools.count(1)
        self._starter: threading.Thread | None = None
        self._closed = False
        self.started_s: list[float] = []  # when each driver joined (monotonic)

    def start(self, timeout_s: float | None = None) -> None:
        """Start the driver and wait until it joined Ray (``timeout_s``, default ``JOIN_S``); a fault is a
        :class:`ClusterError` in one line."""
        timeout = JOIN_S if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        while self.address not in (None, "", "local", "auto"):  # a head starting beside us answers in a moment
            try:
                check_address(self.address, min(timeout, 10.0))
                break
            except Unanswered:
                if time.monotonic() + JOIN_RETRY_S > deadline:
                    raise
                time.sleep(JOIN_RETRY_S)
        timeout = max(0.1, deadline - time.monotonic())
        ours, theirs = socket.socketpair()
        options = {"address": self.address or "local", "retry_s": self.retry_s}
        if self.target is not None:
            options["target"] = [self.target.fps, self.target.width, self.target.height]
        command = [sys.executable, "-m", "rcp_server.cluster.driver", str(theirs.fileno()), json.dumps(options)]
        process = subprocess.Popen(command, pass_fds=[theirs.fileno()], stdin=subprocess.DEVNULL)
        theirs.close()
        pipe = Pipe(ours.detach())
        if not pipe.poll(timeout):
            _end(process, pipe)
            raise ClusterError(
                f"Ray at {self.address or 'local'} was not joined within {timeout_s or JOIN_S:g} s (RCP_RAY_JOIN_S)"
            )
        try:
            said = pipe.recv()
        except (EOFError, OSError):
            said = ("failed", "the Ray driver process exited as it started")
        if said[0] != "joined":
            _end(process, pipe)
            raise ClusterError(said[1])
        with self._lock:
            self._pipe, self._process, self.pid = pipe, process, said[1]
            self.generation += 1
        self.started_s.append(time.monotonic())
        threading.Thread(target=self._read, args=(pipe, process), name="rcp-ray-driver", daemon=True).start()
        log.info("Ray's driver (process %d) joined %s", self.pid, self.address or "a runtime of its own")

    def _read(self, pipe: Pipe, process: subprocess.Popen) -> None:
        while True:
            try:
                message = pipe.recv()
            except (EOFError, OSError, TypeError):  # the driver has gone (or our side was closed under us)
                break
            future = self._pending.pop(message[1], None)
            if future is None:
                continue
            if message[0] == "ok":
                future.set_result(message[2])
            else:
                future.set_exception(_error(*message[2:]))
        with self._lock:
            if self._pipe is not pipe:
                return
            self._pipe = None
        reason = f"Ray's driver (process {process.pid}) exited"
        if not self._closed:
            log.warning("%s: painted on the server until Ray answers again", reason)
            self.backoff.failed(reason)
        for call in list(self._pending):
            future = self._pending.pop(call, None)
            if future is not None:
                future.set_exception(_Down(reason))
        _end(process, pipe)

    def ready(self) -> bool:
        """Whether Ray may be tried now: a driver runs and Ray is not backing off. A driver that died is started
        again on a thread once the wait is over (never on a caller's path)."""
        if self._pipe is None and not self._closed and self.backoff.wait_s() == 0:
            self._restart()
        return self._pipe is not None and self.backoff.wait_s() == 0

    def _restart(self) -> None:
        with self._lock:
            if self._starter is not None and self._starter.is_alive():
                return

            def start() -> None:
                try:
                    self.start(JOIN_S)
                    self.backoff.succeeded()
                    log.info("Ray answers again: walks and films go back to it")
                except ClusterError as exc:
                    self.backoff.failed(f"Ray is still down: {exc}")

            self._starter = threading.Thread(target=start, name="rcp-ray-restart", daemon=True)
            self._starter.start()

    def check(self) -> None:
        """Raises :class:`ClusterError` while Ray backs off or no driver runs."""
        if not self.ready():
            wait = self.backoff.wait_s()
            raise _Down(f"{self.backoff.reason or 'Ray is not joined'} (Ray is tried again in {math.ceil(wait)} s)")


class RemoteRay(DriverProcess):
    """Calls to Ray's driver (:class:`DriverProcess`): a scene sent once, then by its key, a call given up when no
    longer wanted. Paints films and large paintings (:meth:`images`, :meth:`render`) as
    :class:`~.painter.RayPainter` does."""

    def call(self, method: str, *args, should_stop: Callable[[], bool] | None = None, timeout_s: float | None = None):
        """``method(*args)`` in the driver (a scene travels once, then by its key); its answer, or its fault raised
        here again (:class:`ClusterError` when the driver dies meanwhile, :class:`Abandoned` once ``should_stop``
        says so: the driver is told to stop too)."""
        for _ in range(2):
            generation = self.generation
            sent = [self._scene(a, generation) if isinstance(a, Scene) else a for a in args]
            try:
                return self._call(method, sent, should_stop, timeout_s)
            except LookupError:  # the driver let the scene go: sent again
                self._sent.clear()
        raise ClusterError("a scene could not be handed to Ray's driver")

    def _scene(self, scene: Scene, generation: int) -> SceneKey:
        with self._lock:
            entry = self._keys.get(id(scene))
            if entry is None or entry[0] is not scene:
                entry = self._keys[id(scene)] = (scene, next(self._serial))
                while len(self._keys) > SCENES:
                    self._keys.popitem(last=False)
            key = entry[1]
        if self._sent.get(key) != generation:
            # Ray's cloudpickle: a scene may hold functions of its own (an animation's motion)
            from ray import cloudpickle

            self._call("scene", (key, cloudpickle.dumps(portable(scene))), None, None)
            self._sent[key] = generation
        return SceneKey(key)

    def _call(self, method: str, args, should_stop, timeout_s):
        pipe = self._pipe
        if pipe is None:
            raise _Down(self.backoff.reason or "Ray's driver is not running")
        call, future = next(self._calls), Future[Any]()
        self._pending[call] = future
        try:
            with self._sending:
                pipe.send(("call", call, method, tuple(args)))
        except (OSError, ValueError):
            self._pending.pop(call, None)
            raise _Down("Ray's driver has gone") from None
        except Exception as exc:  # what cannot travel to the driver is painted here
            self._pending.pop(call, None)
            raise NoRoom(f"{method} cannot be handed to Ray's driver: {first_line(exc)}") from None
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            try:
                return future.result(POLL_S)
            except FutureTimeout:
                pass
            if (should_stop is not None and should_stop()) or (deadline is not None and time.monotonic() > deadline):
                with self._sending, _quiet():
                    pipe.send(("cancel", call))
                if should_stop is not None and should_stop():
                    raise Abandoned
                raise ClusterError(f"Ray's driver did not answer {method} within {timeout_s:g} s")

    # ---- what the service paints here ----

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
        """One painting from ``I_0`` on Ray, (height, width, 3) uint8 (see :meth:`.RayPainter.render`)."""
        self.check()
        return self._failing(
            lambda: self.call("render", scene, camera, width, height, params, time, should_stop=should_stop)
        )

    def images(
        self,
        scene: Scene,
        shots: Iterable,
        width: int,
        height: int,
        params: PaintParams,
        temporal: int | None = None,
        should_stop: Callable[[], bool] | None = None,
    ) -> Iterator[np.ndarray]:
        """A film's frames on Ray, in order (see :meth:`.RayPainter.images`)."""
        self.check()
        film = self._failing(lambda: self.call("film", scene, list(shots), width, height, params, temporal))
        try:
            while True:
                if should_stop is not None and should_stop():  # frames quicker than a wait's poll stop here too
                    raise Abandoned
                image = self._failing(lambda: self.call("film_next", film, should_stop=should_stop))
                if image is None:
                    return
                yield image
        finally:
            with _quiet():
                self.call("film_close", film, timeout_s=5.0)

    def _failing(self, call: Callable):
        try:
            return call()
        except ClusterError as exc:
            if not isinstance(exc, (PaintingFailed, NoRoom)):
                self.backoff.failed(str(exc))
            raise

    def close(self) -> None:
        """Stop the driver (and the runtime it started)."""
        self._closed = True
        with self._lock:
            pipe, process, self._pipe = self._pipe, self._process, None
        if pipe is not None and process is not None:
            with self._sending, _quiet():
                pipe.send(("close",))
            _end(process, pipe)


class RemoteWalks:
    """The walkers: on Ray while its room holds (the driver's :class:`~.walks.Walks` decides), else on the server's
    own cores while ``local_room`` walkers fit there (the same planner paints them smaller); a walker that fits
    nowhere is refused (:class:`~.admission.Full`). A walker painted here goes to Ray once it has room."""

    def __init__(self, ray: RemoteRay, local_room: int, retry_s: int):
        self.ray = ray
        self.local_room = local_room
        self.retry_s = retry_s
        self.on_ray: dict[int, int] = {}  # walker -> the driver generation that placed it
        self.local: dict[int, float] = {}  # walker -> when it last asked for a place on Ray
        self.local_frames = 0
        self.frames = 0
        self.measured: dict | None = None  # the driver's measure of a frame's cost
        self._figures: dict = {}
        self._asking: threading.Thread | None = None
        self._lock = threading.Lock()

    def calibrate(self, scene: Scene, params: PaintParams) -> dict:
        self.measured = self.ray.call("calibrate", scene, params)
        return self.measured

    def admit(self, key: object, params: PaintParams, scene: Scene | None = None) -> None:
        """A place for walker ``key``: on Ray, else here, else :class:`Full` (one line, with a retry time)."""
        if self.measured is None:  # measured with a walker's own scene off its path (the next try, on a thread)
            reason: str | None = "the cost of a frame on Ray is not measured yet"
        else:
            reason = self._on_ray(id(key), params, scene)
        if reason is None:
            return
        with self._lock:
            if id(key) in self.local or len(self.local) < self.local_room:
                self.local[id(key)] = time.monotonic()
                return
        raise Full(f"{reason}, and the server's own cores hold {self.local_room} walkers, all walking", self.retry_s)

    def _on_ray(self, key: int, params: PaintParams, scene: Scene | None) -> str | None:
        """None once walker ``key`` has a place on Ray; else why not."""
        if not self.ray.ready():
            return "Ray is not answering"
        try:
            self.ray.call("admit", key, params, scene, timeout_s=30.0)
        except Full as full:
            return full.reason
        except ClusterError as exc:
            return str(exc)
        with self._lock:
            self.on_ray[key] = self.ray.generation
            self.local.pop(key, None)
            self.measured = self.measured or {}
        return None

    def leave(self, key: object) -> None:
        with self._lock:
            self.local.pop(id(key), None)
            placed = self.on_ray.pop(id(key), None)
        if placed is not None and placed == self.ray.generation and self.ray.ready():
            threading.Thread(target=self._left, args=(id(key),), daemon=True).start()

    def _left(self, key: int) -> None:
        with _quiet():
            self.ray.call("leave", key, timeout_s=10.0)

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
        """Walker ``key``'s frame on Ray (see :meth:`.Walks.paint`); :class:`NoRoom` when it is painted here (no
        place on Ray yet, Ray down or backing off), :class:`ClusterError` when Ray failed it."""
        walker = id(key)
        if self.on_ray.get(walker) != self.ray.generation or not self.ray.ready():
            self._move(walker, params, scene)
            raise NoRoom("painted on the server")
        args = (walker, scene, camera, width, height, params, scene_time, quality, serial, after, keep_pixels)
        try:
            painted = self.ray.call("paint", *args, should_stop=should_stop)
        except NoRoom:
            raise
        except (Abandoned, PaintingFailed):
            raise
        except ClusterError as exc:
            self.ray.backoff.failed(str(exc))
            raise
        self.frames += 1
        return painted

    def _move(self, walker: int, params: PaintParams, scene: Scene) -> None:
        """A walker painted here asks Ray for a place again, at most every ``LOCAL_TRY_S``, on a thread."""
        with self._lock:
            if time.monotonic() - self.local.get(walker, -math.inf) < LOCAL_TRY_S:
                return
            self.local[walker] = time.monotonic()
            self.on_ray.pop(walker, None)
        if self.ray.ready():
            threading.Thread(target=self._on_ray, args=(walker, params, scene), daemon=True).start()

    def figures(self) -> dict:
        """The walks' figures: the driver's (asked on a thread, never waited for: the last answer) and where each
        walker paints."""
        if self.ray.ready() and not (self._asking is not None and self._asking.is_alive()):
            self._asking = threading.Thread(target=self._ask_figures, name="rcp-ray-figures", daemon=True)
            self._asking.start()
        return {
            **self._figures,
            "on_ray": self.ray.ready(),
            "walkers_on_ray": len(self.on_ray),
            "walkers_here": len(self.local),
            "frames_on_ray": self.frames,
        }

    def _ask_figures(self) -> None:
        with _quiet():
            self._figures = self.ray.call("figures", timeout_s=5.0)

    def close(self) -> None:
        with self._lock:
            self.on_ray.clear()
            self.local.clear()


def _error(kind: str, line: str, retry: int | None) -> Exception:
    if kind == "Full":
        return Full(line, retry or 30)
    if kind == "Abandoned":
        return Abandoned()
    if kind == "LookupError":
        return LookupError(line)
    return ERRORS.get(kind, ClusterError)(line)


def _end(process: subprocess.Popen, pipe: Pipe) -> None:
    with _quiet():
        pipe.close()
    try:
        process.wait(5.0)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


class _quiet:
    """Nothing to do about a failure here (a driver that has gone already)."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, exc, tb) -> bool:
        return kind is not None and issubclass(kind, Exception)
