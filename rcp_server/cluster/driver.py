"""Ray's driver, in a process of its own: the server talks to it over a socket and outlives it.

Ray ends a driver whose raylet dies (and, past a timeout, one that lost its head): the process that serves must not
be that driver. This module is the child's side: it joins Ray on its main thread (Ray's processes die with the
thread that started them), says so, then answers the server's calls (a walk frame, a render, a film's frames,
admission) each on a thread of its own, until the server closes the socket or Ray ends this process. The server's
side is :mod:`.remote`.

Messages (pickled, on a ``multiprocessing.connection`` over the socket): the server sends ``("call", id, method,
args)`` and ``("cancel", id)``; the child answers ``("ok", id, value)`` or ``("error", id, kind, line, retry)``.
Scenes travel once per driver (``scene``) and are named by key afterwards (:class:`SceneKey`).
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import pickle
import socket
import sys
import threading
import time
from collections import OrderedDict
from collections.abc import Generator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from multiprocessing.connection import Connection as Pipe

from ..painting.loop import Abandoned
from ..painting.sequence import Shot
from ..scene.scene import Scene
from .admission import Full, Target
from .connection import ClusterError, PaintingFailed, first_line
from .painter import RayPainter
from .walks import NoRoom, Walks

log = logging.getLogger("rcp")

SCENES = 8  # scenes the driver keeps (the server sends one again if it was let go)
CALLS = 64  # calls answered at once


@dataclass(frozen=True)
class SceneKey:
    """A scene the server sent this driver earlier, by its key."""

    key: int


def error_of(exc: BaseException) -> tuple[str, str, int | None]:
    """How a call's failure travels: its kind (the class the server raises again), one line, a retry time."""
    for kind in (Full, NoRoom, PaintingFailed, ClusterError, Abandoned, ValueError):
        if isinstance(exc, kind):
            line = exc.reason if isinstance(exc, Full) else str(exc)
            return kind.__name__, line, getattr(exc, "retry_after", None)
    return "ClusterError", f"Ray failed: {first_line(exc)}", None


class Host:
    """What the driver holds: the painter of films and large paintings, and the walkers, on one connection and one
    object-store scene cache."""

    def __init__(self, painter: RayPainter, target: Target | None, retry_s: int):
        self.painter = painter
        self.walks = Walks(painter.connection, target, retry_s, painter.scenes) if target is not None else None
        self.scenes: OrderedDict[int, Scene] = OrderedDict()
        self.films: dict[int, Generator] = {}
        self.stops: dict[int, threading.Event] = {}
        self._serial = itertools.count(1)

    def scene(self, key: int, fields: bytes) -> None:
        self.scenes[key] = Scene(**pickle.loads(fields))
        while len(self.scenes) > SCENES:
            self.scenes.popitem(last=False)

    def resolve(self, value):
        if isinstance(value, SceneKey):
            scene = self.scenes.get(value.key)
            if scene is None:
                raise LookupError(value.key)
            self.scenes.move_to_end(value.key)
            return scene
        return value

    # ---- the calls (``stop``: the server no longer wants the answer) ----

    def calibrate(self, stop, scene, params) -> dict:
        assert self.walks is not None
        frame_s, ray_s = self.walks.calibrate(scene, params)
        return {"frame_s": frame_s, "ray_s": ray_s, "describe": self.walks.describe(params)}

    def target(self, stop, fps: float, width: int, height: int) -> None:
        assert self.walks is not None
        self.walks.target = Target(fps, width, height)

    def capacity(self, stop, params) -> int:
        assert self.walks is not None
        return self.walks.capacity(params)

    def admit(self, stop, key, params, scene) -> None:
        assert self.walks is not None
        if self.walks.cost.ray_s is None and scene is not None:  # not measured at the start: this walker's scene
            self.walks.calibrate(scene, params)
        self.walks.admit(key, params, scene)

    def leave(self, stop, key) -> None:
        if self.walks is not None:
            self.walks.leave(key)

    def paint(self, stop, key, scene, camera, width, height, params, scene_time, quality, serial, after, keep):
        assert self.walks is not None
        return self.walks.paint(
            key, scene, camera, width, height, params, scene_time, quality, serial, after, stop.is_set, keep
        )

    def figures(self, stop) -> dict:
        return {} if self.walks is None else self.walks.figures()

    def groups(self, stop) -> dict:
        """Ray's placement groups, from its own table: id -> state, strategy and the node of each bundle."""
        from ray.util import placement_group_table

        return {
            gid: {"state": g["state"], "strategy": g["strategy"], "nodes": list(g["bundles_to_node_id"].values())}
            for gid, g in placement_group_table().items()
        }

    def cost(self, stop):
        return None if self.walks is None else (self.walks.cost.frame_s, self.walks.cost.ray_s)

    def render(self, stop, scene, camera, width, height, params, time):
        return self.painter.render(scene, camera, width, height, params, time, stop.is_set)

    def film(self, stop, scene, shots: list[Shot], width, height, params, temporal) -> int:
        film = next(self._serial)
        halt = self.stops[film] = threading.Event()
        frames = self.painter.images(scene, shots, width, height, params, temporal, halt.is_set)
        self.films[film] = frames  # type: ignore[assignment]  # a generator: closed with the film
        return film

    def film_next(self, stop, film: int):
        """The film's next frame, None after its last."""
        return next(self.films[film], None)

    def film_close(self, stop, film: int) -> None:
        halt = self.stops.pop(film, None)
        if halt is not None:
            halt.set()
        frames = self.films.pop(film, None)
        if frames is not None:
            frames.close()

    def pid(self, stop) -> int:
        return os.getpid()


def serve(pipe: Pipe, host: Host) -> None:
    """Answer the server's calls until it closes the socket."""
    sending = threading.Lock()
    stops: dict[int, threading.Event] = {}

    def answer(call: int, method: str, args: tuple) -> None:
        stop = stops[call]
        try:
            message: tuple
            if method == "scene":
                host.scene(*args)
                message = ("ok", call, None)
            else:
                value = getattr(host, method)(stop, *[host.resolve(a) for a in args])
                message = ("ok", call, value)
        except LookupError as exc:  # a scene let go: the server sends it again
            message = ("error", call, "LookupError", str(exc), None)
        except BaseException as exc:  # every fault goes back to the caller in one line
            if not isinstance(exc, (Full, NoRoom, PaintingFailed, ClusterError, Abandoned, ValueError)):
                log.warning("the Ray driver's %s failed: %s", method, first_line(exc))
            message = ("error", call, *error_of(exc))
        finally:
            stops.pop(call, None)
        with sending:
            try:
                pipe.send(message)
            except OSError:  # the server has gone: so does this process, at its next read
                pass

    with ThreadPoolExecutor(CALLS, thread_name_prefix="rcp-driver") as calls:
        while True:
            try:
                message = pipe.recv()
            except (EOFError, OSError):
                break
            if message[0] == "call":
                _, call, method, args = message
                stops[call] = threading.Event()
                calls.submit(answer, call, method, args)
            elif message[0] == "cancel" and message[1] in stops:
                stops[message[1]].set()
            elif message[0] == "close":
                break
        for stop in list(stops.values()):
            stop.set()


WATCH_S = 1.0  # how often the driver checks that its raylet and Ray's head still answer
WATCH_MISSES = 3  # checks in a row without an answer: this driver ends, and the server starts another


def watch() -> None:
    """End this process once its raylet or Ray's head (the GCS) stops taking connections: a driver whose runtime
    died may hang rather than exit, and the server only starts a new one once this one has gone."""
    import ray

    node = ray._private.worker.global_worker.node
    ends = [(node.node_ip_address, node.node_manager_port), _host_port(node.gcs_address)]
    misses = 0
    while True:
        time.sleep(WATCH_S)
        try:
            for end in ends:
                with socket.create_connection(end, timeout=WATCH_S):
                    pass
            misses = 0
        except OSError:
            misses += 1
            if misses >= WATCH_MISSES:
                log.warning("Ray's runtime stopped answering: its driver ends")
                os._exit(3)


def _host_port(address: str) -> tuple[str, int]:
    host, _, port = address.rpartition(":")
    return host, int(port)


def main() -> None:
    """The child: ``python -m rcp_server.cluster.driver FD OPTIONS``: joins Ray, says so, serves, then stops Ray."""
    logging.basicConfig(level=os.environ.get("RCP_LOG_LEVEL", "WARNING"), format="%(levelname)s: %(message)s")
    fd, options = int(sys.argv[1]), json.loads(sys.argv[2])
    pipe = Pipe(socket.socket(fileno=fd).detach())
    stderr = os.dup(2)
    os.dup2(os.open(os.devnull, os.O_WRONLY), 2)  # Ray's own lines while it joins: a failure is said in one line
    try:
        painter = RayPainter(options["address"])
        painter.connection.join()  # here, on the main thread
        walk = options.get("target")
        host = Host(painter, Target(*walk) if walk else None, options.get("retry_s", 30))
    except BaseException as exc:
        pipe.send(("failed", first_line(exc)))
        return
    finally:
        os.dup2(stderr, 2)
    pipe.send(("joined", os.getpid()))
    try:
        threading.Thread(target=watch, name="rcp-ray-watch", daemon=True).start()
    except Exception as exc:  # a client connection (ray://) has no raylet here: Ray's own errors end it
        log.info("the driver does not watch its runtime: %s", first_line(exc))
    try:
        serve(pipe, host)
    finally:
        if host.walks is not None:
            host.walks.close()
        painter.close()
        os._exit(0)  # Ray's threads stop with the process; nothing more to wait for


if __name__ == "__main__":  # run as the module itself, so that its types are the ones the server pickles
    from rcp_server.cluster import driver

    driver.main()
