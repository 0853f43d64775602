"""``rcp bench soak``: a real ``rcp serve`` under a bounded mixed load, and what the process keeps afterwards.

The server is a subprocess (``python -m rcp_server.cli serve``) on 127.0.0.1 and a free port, so its memory and
threads are its own, read from ``/proc/<pid>/status`` (``VmRSS``, ``Threads``). A warm-up round first walks
every scene over the WebSocket and renders over REST more paintings at once than the server runs, so compiled
kernels, scene caches and every worker thread exist before the baseline is taken. Then, for ``seconds``:

- ``clients`` WebSocket walk-throughs at 160x90, each moving the camera at 30 Hz on a small circle for 3 s and
  resting 1 s (so the server paints walk frames and refinements); clients 1, 3, 5... close and reconnect at a
  third and at two thirds of the run; client 0 drops its TCP connection (a reset, no close handshake) while a
  refinement is being painted, in the middle of the run, and comes back.
- ``rest`` callers posting 160x90 renders back to back.

After all clients have left, the server settles until it reports no sessions, and the process is measured again.
Then it is stopped with SIGINT, as a terminal would, and must exit with 0. Every wait on the server has a timeout,
and the subprocess is killed if it does not stop, so a misbehaving server ends the soak instead of hanging it.
"""

from __future__ import annotations

import asyncio
import collections
import http.client
import json
import math
import socket
import struct
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from ..service.loopback import TIMEOUT, Answer, ProcessSample, Served, get_json, rcp_serve, request
from .latency import percentile

WIDTH, HEIGHT = 160, 90  # the walk-through canvas and the REST image
CAMERA_HZ = 30.0  # camera messages per second while a client walks
WALK_S, REST_S = 3.0, 1.0  # each client walks this long, then rests this long (and the server refines)
SETTLE_S = 1.0  # after the sessions are gone, before the last measurement
GIVE_BACK_S = 10.0  # the closed walks' memory goes back to the system off their path: the least RSS over this long
WARM_RENDERS = 8  # REST renders at once in the warm-up: more than the server's default max_renders (4)
SAMPLE_S = 0.2  # how often the process is measured during the load


# ---- the report ----


@dataclass
class ClientFigures:
    """One WebSocket client over the whole soak, across its connections."""

    scene: str
    role: str  # steady, reconnects (closes cleanly twice), drops (one connection reset mid-refinement)
    connection_frames: list[int] = field(default_factory=list)  # frames received on each connection, in order
    latencies_ms: list[float] = field(default_factory=list, repr=False)  # camera message sent -> its walk frame

    @property
    def connections(self) -> int:
        return len(self.connection_frames)

    @property
    def frames(self) -> int:
        """Frames received, each a frame message and its JPEG."""
        return sum(self.connection_frames)


@dataclass
class SoakReport:
    seconds: float
    clients: int
    rest_callers: int
    client_figures: list[ClientFigures]
    rest_renders: int  # REST renders answered 200 with an image
    rest_status: dict[int, int]  # status code -> how many
    errors: list[str]  # error messages from the server, failed or timed-out calls, wrong answers
    rss_before_mb: float
    rss_peak_mb: float
    rss_after_mb: float
    threads_before: int
    threads_peak: int
    threads_after: int
    sessions_after: int
    server_log: list[str] = field(default_factory=list)  # the server's warnings, errors and tracebacks
    exit_code: int | None = None  # of rcp serve on SIGINT; None: it had to be killed

    @property
    def frames(self) -> list[int]:
        return [c.frames for c in self.client_figures]

    def lines(self) -> list[str]:
        out = [
            f"rcp bench soak: {self.seconds:.0f} s, {self.clients} WebSocket clients at {WIDTH}x{HEIGHT} (camera at "
            f"{CAMERA_HZ:.0f} Hz, {WALK_S:.0f} s walking then {REST_S:.0f} s resting), {self.rest_callers} REST "
            f"callers ({WIDTH}x{HEIGHT} renders back to back)",
            f"{'client':>6} {'scene':>8} {'role':>10} {'frames':>6} {'per connection':>14} {'fps':>5} "
            f"{'latency p50':>11} {'p95':>6}",
        ]
        for k, c in enumerate(self.client_figures):
            out.append(
                f"{k:>6} {c.scene:>8} {c.role:>10} {c.frames:>6} {'+'.join(map(str, c.connection_frames)):>14} "
                f"{c.frames / self.seconds:5.1f} {percentile(c.latencies_ms, 50):11.1f} "
                f"{percentile(c.latencies_ms, 95):6.1f}"
            )
        out.append("latency: camera message sent -> the walk frame showing it received, in ms")
        statuses = ", ".join(f"{code} x{n}" for code, n in sorted(self.rest_status.items())) or "none"
        out += [
            f"REST: {self.rest_renders} renders ({self.rest_renders / self.seconds:.1f}/s); status codes: {statuses}",
            f"{'':>12} {'before':>8} {'peak':>8} {'after':>8}",
            f"{'RSS (MB)':>12} {self.rss_before_mb:8.1f} {self.rss_peak_mb:8.1f} {self.rss_after_mb:8.1f}",
            f"{'threads':>12} {self.threads_before:8d} {self.threads_peak:8d} {self.threads_after:8d}",
            f"sessions after: {self.sessions_after}; rcp serve on SIGINT: "
            + ("killed (did not stop)" if self.exit_code is None else f"exit code {self.exit_code}"),
        ]
        counted = collections.Counter(self.errors)
        out.append(f"errors: {len(self.errors) or 'none'}")
        out += [f"  {n} x {message}" for message, n in counted.most_common()]
        out.append(f"server log warnings and errors: {len(self.server_log) or 'none'}")
        out += [f"  {line}" for line in self.server_log[:20]]
        return out


# ---- the clients ----


def _camera_message(scene: dict, k: int) -> dict:
    """The k-th camera of a walk: the scene's camera carried around a small horizontal circle (one turn in
    ``WALK_S``), looking the same way, with ``id`` k."""
    eye, look_at = np.array(scene["camera"]["eye"]), np.array(scene["camera"]["look_at"])
    radius = 0.05 * float(np.linalg.norm(look_at - eye))
    angle = 2 * math.pi * k / (CAMERA_HZ * WALK_S)
    offset = radius * np.array([math.cos(angle) - 1, 0.0, math.sin(angle)])
    return {"type": "camera", "eye": list(eye + offset), "look_at": list(look_at + offset), "id": k}


def _reset(ws: ClientConnection) -> None:
    """Drop the connection as a crashed client would: a TCP reset, no WebSocket close handshake."""
    sock = ws.transport.get_extra_info("socket")
    if sock is not None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    ws.transport.abort()


class _Client:
    """A walk-through client: connections (legs) of hello, walking and resting, with a reader per leg."""

    def __init__(self, index: int, scene: dict, role: str, errors: list[str]):
        self.index, self.scene, self.errors = index, scene, errors
        self.figures = ClientFigures(scene["name"], role)
        self.k = 0  # camera messages sent, over every connection
        self.sent: dict[int, float] = {}

    async def run(self, ws_url: str, start: float, seconds: float) -> None:
        role = self.figures.role
        if role == "reconnects":
            ends = [(start + seconds * j / 3, "close") for j in (1, 2, 3)]
        elif role == "drops":
            ends = [(start + seconds / 2, "reset"), (start + seconds, "close")]
        else:
            ends = [(start + seconds, "close")]
        for until, end in ends:
            if not await self._leg(ws_url, until, end):
                return

    async def _leg(self, ws_url: str, until: float, end: str) -> bool:
        """One connection until ``until`` (monotonic s), ended by a clean close or a reset; False if it failed."""
        refining = asyncio.Event()  # set by a refinement that another one follows: painting goes on server-side
        try:
            ws = await connect(ws_url, max_size=None, open_timeout=TIMEOUT, close_timeout=5)
        except (OSError, TimeoutError) as exc:
            self.errors.append(f"client {self.index}: cannot connect: {exc!r}")
            return False
        self.figures.connection_frames.append(0)
        reader = asyncio.create_task(self._read(ws, refining))
        reset = False
        try:
            hello = {"type": "hello", "scene": self.scene["name"], "width": WIDTH, "height": HEIGHT}
            await ws.send(json.dumps(hello))
            await self._move(ws, until, reader)
            if end == "reset" and not reader.done():
                # one more step, so that a refinement follows even if the camera already rests and is refined
                refining.clear()
                await self._step(ws)
                refined = asyncio.create_task(refining.wait())
                await asyncio.wait([refined, reader], timeout=TIMEOUT, return_when=asyncio.FIRST_COMPLETED)
                refined.cancel()
                if not refining.is_set():
                    self.errors.append(f"client {self.index}: no refinement to drop the connection in")
                _reset(ws)
                reset = True
            return not reader.done()
        except ConnectionClosed as exc:
            self.errors.append(f"client {self.index}: the server closed the connection: {exc}")
            return False
        finally:
            reader.cancel()
            await asyncio.gather(reader, return_exceptions=True)
            if not reset:
                async with asyncio.timeout(TIMEOUT):
                    await ws.close()

    async def _move(self, ws: ClientConnection, until: float, reader: asyncio.Task) -> None:
        """Walk for ``WALK_S`` and rest for ``REST_S``, in turn, until ``until`` or the reader stops."""
        period, cycle = 1 / CAMERA_HZ, WALK_S + REST_S
        begun = time.monotonic()
        while (now := time.monotonic()) < until and not reader.done():
            if (now - begun) % cycle < WALK_S:
                await self._step(ws)
            await asyncio.sleep(min(period, max(until - time.monotonic(), 0)))

    async def _step(self, ws: ClientConnection) -> None:
        self.sent[self.k] = time.monotonic()
        await ws.send(json.dumps(_camera_message(self.scene, self.k)))
        self.k += 1

    async def _read(self, ws: ClientConnection, refining: asyncio.Event) -> None:
        meta = None
        while True:
            try:
                # asyncio.timeout, not wait_for: Python 3.11's wait_for can swallow the cancellation that ends a
                # connection when a message arrives at the same moment, and the reader would wait on
                async with asyncio.timeout(TIMEOUT):
                    message = await ws.recv()
            except TimeoutError:
                self.errors.append(f"client {self.index}: no message from the server for {TIMEOUT:.0f} s")
                return
            except ConnectionClosed as exc:
                self.errors.append(f"client {self.index}: the server closed the connection: {exc}")
                return
            if isinstance(message, bytes):
                if meta is None:
                    self.errors.append(f"client {self.index}: a binary message without its frame message")
                    continue
                self.figures.connection_frames[-1] += 1
                if meta["phase"] == "walk" and meta["camera_id"] in self.sent:
                    self.figures.latencies_ms.append((time.monotonic() - self.sent[meta["camera_id"]]) * 1000)
                if meta["phase"] == "refine" and not meta["final"]:
                    refining.set()
                meta = None
                continue
            msg = json.loads(message)
            if msg["type"] == "frame":
                meta = msg
            elif msg["type"] == "error":
                self.errors.append(f"client {self.index}: server says: {msg['message']}")


# ---- REST callers ----


async def _post(pool: ThreadPoolExecutor, url: str, body: dict) -> Answer:
    """``request`` on a thread of ``pool``, one per caller, so that the callers post at the same time."""
    return await asyncio.get_running_loop().run_in_executor(pool, request, url, body)


@dataclass
class _RestLoad:
    renders: int = 0
    status: collections.Counter = field(default_factory=collections.Counter)


async def _rest_caller(pool: ThreadPoolExecutor, url: str, scene: str, until: float, load: _RestLoad, errors: list):
    body = {"scene": scene, "width": WIDTH, "height": HEIGHT, "format": "jpeg"}
    while time.monotonic() < until:
        try:
            answer = await _post(pool, f"{url}/api/render", body)
        except (OSError, http.client.HTTPException) as exc:  # refused, reset, timed out, or not HTTP
            errors.append(f"REST: {exc!r}")
            await asyncio.sleep(0.1)
            continue
        load.status[answer.status] += 1
        if answer.status != 200:
            errors.append(f"REST: {answer.status} {answer.body[:200].decode(errors='replace')}")
        elif answer.content_type != "image/jpeg" or not answer.body.startswith(b"\xff\xd8"):
            errors.append(f"REST: 200 but not a JPEG ({answer.content_type})")
        else:
            load.renders += 1


# ---- the run ----


async def _warm_up(served: Served, scenes: list[dict]) -> None:
    """Every scene walked to its final refinement, and ``WARM_RENDERS`` REST renders at once."""

    async def walk(scene: dict) -> None:
        async with connect(served.ws_url, max_size=None, open_timeout=TIMEOUT) as ws:
            await ws.send(json.dumps({"type": "hello", "scene": scene["name"], "width": WIDTH, "height": HEIGHT}))
            while True:
                async with asyncio.timeout(TIMEOUT):
                    msg = json.loads(await ws.recv())
                if msg["type"] == "error":
                    raise RuntimeError(f"warm-up walk of {scene['name']}: {msg['message']}")
                if msg["type"] == "frame":
                    async with asyncio.timeout(TIMEOUT):
                        await ws.recv()
                    if msg["final"]:
                        return

    with ThreadPoolExecutor(WARM_RENDERS) as pool:

        async def render(k: int) -> None:
            body = {"scene": scenes[k % len(scenes)]["name"], "width": WIDTH, "height": HEIGHT, "format": "jpeg"}
            answer = await _post(pool, f"{served.url}/api/render", body)
            if answer.status != 200:
                raise RuntimeError(f"warm-up render: {answer.status} {answer.body[:200].decode(errors='replace')}")

        await asyncio.gather(*(walk(scene) for scene in scenes), *(render(k) for k in range(WARM_RENDERS)))


async def _load(served: Served, scenes: list[dict], seconds: float, clients: int, rest: int):
    errors: list[str] = []
    load = _RestLoad()
    roles = ["drops" if k == 0 else "reconnects" if k % 2 else "steady" for k in range(clients)]
    walkers = [_Client(k, scenes[k % len(scenes)], roles[k], errors) for k in range(clients)]
    samples: list[ProcessSample] = []
    start = time.monotonic()
    until = start + seconds

    async def sample() -> None:
        while True:
            try:
                samples.append(served.sample())
            except FileNotFoundError:
                errors.append("the server process is gone")
                return
            await asyncio.sleep(SAMPLE_S)

    sampler = asyncio.create_task(sample())
    with ThreadPoolExecutor(max(rest, 1)) as pool:
        tasks = [asyncio.create_task(c.run(served.ws_url, start, seconds)) for c in walkers]
        tasks += [
            asyncio.create_task(_rest_caller(pool, served.url, scenes[k % len(scenes)]["name"], until, load, errors))
            for k in range(rest)
        ]
        _, pending = await asyncio.wait(tasks, timeout=seconds + 3 * TIMEOUT)
        for task in pending:
            task.cancel()
        if pending:
            errors.append(f"{len(pending)} clients still busy {3 * TIMEOUT:.0f} s after the end: cancelled")
        for result in await asyncio.gather(*tasks, return_exceptions=True):
            if isinstance(result, BaseException) and not isinstance(result, asyncio.CancelledError):
                errors.append(f"client failed: {result!r}")
    sampler.cancel()
    return [c.figures for c in walkers], load, errors, samples


def _sessions(served: Served) -> int:
    return get_json(f"{served.url}/api/health")["sessions"]


def soak(seconds: float = 60.0, clients: int = 6, rest: int = 2) -> SoakReport:
    """Start ``rcp serve``, warm it up, measure it, load it for ``seconds``, let it settle, measure it again."""
    with tempfile.TemporaryDirectory(prefix="rcp-soak-") as tmp, rcp_serve(Path(tmp)) as served:
        scenes = get_json(f"{served.url}/api/scenes")
        asyncio.run(asyncio.wait_for(_warm_up(served, scenes), 4 * TIMEOUT))
        _sessions(served)  # the health endpoint's worker thread exists before the baseline, as after
        time.sleep(SETTLE_S)
        before = served.sample()
        figures, load, errors, samples = asyncio.run(_load(served, scenes, seconds, clients, rest))
        # ---- settle: every session gone, then a moment for paintings in flight to stop ----
        deadline = time.monotonic() + TIMEOUT
        while (sessions := _sessions(served)) and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(SETTLE_S)
        sessions = _sessions(served)
        after = served.sample()
        given_back = time.monotonic() + GIVE_BACK_S
        while after.rss_mb > before.rss_mb and time.monotonic() < given_back:
            time.sleep(0.5)
            after = min(after, served.sample(), key=lambda sample: sample.rss_mb)
        samples = [before, *samples, after]
        exit_code = served.stop()
        return SoakReport(
            seconds=seconds,
            clients=clients,
            rest_callers=rest,
            client_figures=figures,
            rest_renders=load.renders,
            rest_status=dict(load.status),
            errors=errors,
            rss_before_mb=before.rss_mb,
            rss_peak_mb=max(s.rss_mb for s in samples),
            rss_after_mb=after.rss_mb,
            threads_before=before.threads,
            threads_peak=max(s.threads for s in samples),
            threads_after=after.threads,
            sessions_after=sessions,
            server_log=served.log_problems(),
            exit_code=exit_code,
        )


def bench_soak(seconds: float, clients: int, rest: int) -> SoakReport:
    """``rcp bench soak``: run it and print the report."""
    report = soak(seconds, clients, rest)
    print("\n".join(report.lines()))
    return report
