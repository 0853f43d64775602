"""Painting sequences on Ray: the same frames as the threads of one machine, pixel for pixel, on many.

Workers are Ray actors, each holding a warm scene: the scene's arrays are put in the object store once per
scene, and each actor builds its BVH itself (an Embree handle cannot travel). What a frame needs (camera,
time, settings) is a few hundred bytes; what comes back is the frame as uint8, 3 bytes a pixel, through
the object store, in order, with a bounded number of frames in flight.

What the method allows decides how the work splits (``sequence.py`` has the per-frame/temporal rule):

* per frame: frames are independent, so they go round the actors;
* temporal, ray-traced: a pixel reads only its own previous value, so a band of rows runs through every
  iteration *and every frame* on one actor, keeping its own previous state: no exchange between bands;
* temporal, image method: its lookups reach the whole screen, so whole frames run in order on one actor.

Ray is the ``cluster`` extra; nothing else imports this module unless asked for Ray.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, fields
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from . import images
from .camera import Camera, Region
from .painting import Abandoned, PaintState, paint
from .params import PaintParams
from .scene import Scene
from .sequence import Shot, frame_params

log = logging.getLogger("rcp")

CONNECT_TIMEOUT_S = 10.0
"""How long an address may take to answer at all before we say it does not (``ray.init`` itself retries a
silent address for minutes)."""
IN_FLIGHT_PER_ACTOR = 2  # frames (or bands) queued on each actor: one painting, one ready to start


class ClusterError(RuntimeError):
    """Ray cannot be used as asked (not installed, an address that does not answer, a worker lost); one line."""


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
        raise ClusterError(f"Ray address {address} does not answer ({reason})") from None


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


# ---- the scene as it travels ----


def portable(scene: Scene) -> dict:
    """What a scene is, without what it caches (BVHs, locks): its public fields, as ``Scene(**fields)``."""
    return {f.name: getattr(scene, f.name) for f in fields(scene) if not f.name.startswith("_")}


class Painter:
    """One Ray actor's work: paints frames, or one band of rows through every frame, of a warm scene.

    ``previous`` keeps the last painting of each temporal band this actor paints (by job), so a band's
    recursion continues here, frame after frame, with nothing sent back and forth but the band's pixels."""

    def __init__(self, scene: dict, threads: int):
        self.scene = Scene(**scene)
        self.scene.geometry(0.0)  # the BVH, built here once, before the first frame waits for it
        self.threads = threads
        self.previous: dict[tuple[str, Region], PaintState] = {}

    def frame(self, shot: tuple[Camera, float], width: int, height: int, params: PaintParams) -> np.ndarray:
        """A whole frame from ``I_0``: (height, width, 3) uint8."""
        camera, time = shot
        return images.to_uint8(paint(self.scene, camera, width, height, params, time=time, threads=self.threads).image)

    def band(
        self, job: str, region: Region, shot: tuple[Camera, float], params: PaintParams, first: bool
    ) -> np.ndarray:
        """The rows of ``region`` of the next frame of ``job``, continuing from this band's previous frame
        (from ``I_0`` when ``first``): (rows, width, 3) uint8. The image method takes the whole frame."""
        camera, time = shot
        previous = None if first else self.previous.get((job, region))
        result = paint(
            self.scene,
            camera,
            region.full_width,
            region.full_height,
            params,
            time=time,
            previous=previous,
            region=region,
            threads=self.threads,
        )
        self.previous[(job, region)] = result.state
        return images.to_uint8(result.image)

    def forget(self, job: str) -> None:
        self.previous = {key: state for key, state in self.previous.items() if key[0] != job}

    def ready(self) -> bool:
        return True


@dataclass
class _Crew:
    """The actors of one scene, and the scene they hold."""

    scene: Scene
    actors: list


class RayPainter:
    """Paints sequences on Ray actors (``threads`` CPUs each; as many actors as the cluster has CPUs for),
    one sequence at a time, the scene's actors kept warm for the next sequence of the same scene (a new
    scene replaces them: actors hold their CPUs, and a second crew would wait for them forever).
    ``address``: as :func:`connect`."""

    def __init__(self, address: str | None = None, threads: int = 1, actors: int | None = None, num_cpus=None):
        self.address = address
        self.threads = threads
        self._wanted = actors
        self._num_cpus = num_cpus
        self._started = False
        self._connected = False
        self._crews: dict[int, _Crew] = {}
        self._lock = threading.Lock()
        self._one_at_a_time = threading.Lock()
        self._jobs = 0

    def start(self) -> None:
        """Join (or start) Ray now, rather than with the first sequence; raises :class:`ClusterError`."""
        with self._lock:
            self._start()

    def _start(self) -> None:
        if not self._connected:
            self._started = connect(self.address, self._num_cpus)
            self._connected = True

    def crew(self, scene: Scene) -> list:
        """The actors holding ``scene``, started (and the scene put in the object store) on first use."""
        with self._lock:
            self._start()
            ray = _ray()
            crew = self._crews.get(id(scene))
            if crew is None or crew.scene is not scene:
                for old in self._crews.values():
                    for actor in old.actors:
                        ray.kill(actor)
                self._crews.clear()
                count = self._wanted or max(1, int(ray.cluster_resources().get("CPU", 1) // self.threads))
                remote = ray.remote(num_cpus=self.threads, max_restarts=0)(Painter)
                held = ray.put(portable(scene))  # once: every actor reads the same arrays
                actors = [remote.remote(held, self.threads) for _ in range(count)]
                crew = self._crews[id(scene)] = _Crew(scene, actors)
            return crew.actors

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
        ``sequence.paint_sequence`` paints with threads. Raises :class:`ClusterError` when a worker is lost,
        :class:`~.paintstate.Abandoned` once ``should_stop`` says so."""
        ray = _ray()
        with self._one_at_a_time:
            yield from self._images(ray, scene, shots, width, height, params, temporal, should_stop)

    def _images(self, ray, scene, shots, width, height, params, temporal, should_stop) -> Iterator[np.ndarray]:
        actors = self.crew(scene)
        with self._lock:
            self._jobs += 1
            job = f"job-{self._jobs}"
        pending: deque = deque()  # (refs of one frame, in order)
        if temporal and params.method == "raytrace":
            rows = -(-height // len(actors))
            bands = Region(width, height).tiles(rows)
            workers = list(zip(actors, bands, strict=False))
        elif temporal:
            workers = [(actors[0], Region(width, height))]
        else:
            workers = []
        limit = IN_FLIGHT_PER_ACTOR * (len(actors) if not temporal else 1)

        def submit(index: int, shot: Shot) -> list:
            p = frame_params(params, temporal, index)
            when = (shot.camera, shot.scene_time)
            if not temporal:
                return [actors[index % len(actors)].frame.remote(when, width, height, p)]
            return [actor.band.remote(job, band, when, p, index == 0) for actor, band in workers]

        def take() -> np.ndarray:
            refs = pending.popleft()
            try:
                parts = ray.get(refs)
            except ray.exceptions.RayActorError as exc:
                self._drop(scene)
                raise ClusterError(f"a Ray worker was lost mid-job: {_first_line(exc)}") from None
            except ray.exceptions.RayTaskError as exc:
                raise ClusterError(f"a frame failed on Ray: {_first_line(exc)}") from None
            return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=0)

        try:
            for index, shot in enumerate(shots):
                if should_stop is not None and should_stop():
                    raise Abandoned
                pending.append(submit(index, shot))
                if len(pending) >= limit:
                    yield take()
            while pending:
                if should_stop is not None and should_stop():
                    raise Abandoned
                yield take()
        finally:
            for refs in pending:  # abandoned or failed: what is still queued is not painted
                for ref in refs:
                    try:
                        ray.cancel(ref)
                    except Exception:  # finished meanwhile, or its actor is gone: nothing left to stop
                        pass
            if temporal:
                for actor, _ in workers:
                    actor.forget.remote(job)

    def _drop(self, scene: Scene) -> None:
        """Forget a crew that lost an actor: the next sequence starts a new one."""
        with self._lock:
            crew = self._crews.pop(id(scene), None)
        if crew is not None:
            for actor in crew.actors:
                _ray().kill(actor)

    def close(self) -> None:
        """Stop the actors, and Ray itself if this painter started it."""
        if not self._connected:
            return
        ray = _ray()
        for scene_id in list(self._crews):
            for actor in self._crews.pop(scene_id).actors:
                ray.kill(actor)
        if self._started:
            ray.shutdown()
        self._connected = False
