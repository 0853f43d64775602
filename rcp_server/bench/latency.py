"""``rcp bench latency``: how the walk-through feels, measured over loopback against a real server.

A WebSocket client walks the default scene in a 1280x720 window, per frame (the default: every frame the
painting of its camera) and temporal: it sends a camera message every 1/60 s along a straight path, as a
held key does, and records for every frame the time from sending the camera message the frame shows to
receiving the frame, and the frame's size. Then it rests, and moves single steps, timing each step's
first frame, its first full-size painting and its final (refined) one. Beside that, the same paintings
timed alone in this process: all iterations from the canvas (per-frame), one from the last frame
(temporal). Last, the per-frame walk again under load: while a REST caller asks for large paintings back to
back (+REST), and while a video job paints on the same tile pool (+video; its frames a second before and
during the walk are printed beside it).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import statistics
import threading
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import websockets

from ..painting.loop import paint
from ..scene.scenefile import load_scene
from ..service.loopback import BackgroundServer, get_json, request
from ..settings.params import PaintParams

WINDOW = (1280, 720)
RATE = 60.0  # camera messages per second while walking


@dataclass
class WalkFigures:
    frames: int
    seconds: float
    latencies_ms: list[float]
    render_ms: list[float]
    scales: list[float]
    pixels: list[int]  # of each walk frame
    step_ms: list[float]  # one step from rest -> its first frame
    full_ms: list[float]  # ... -> its first painting at full size
    final_ms: list[float]  # ... -> its final, refined painting

    @property
    def fps(self) -> float:
        return self.frames / self.seconds


def percentile(values: list[float], q: float) -> float:
    """The ``q``-th percentile (0..100) of ``values``; NaN for none."""
    return float(np.percentile(values, q)) if values else float("nan")


class _Walker:
    """One walk-through over the WebSocket, as ``rcp bench latency`` times it: camera messages sent, frames read."""

    def __init__(self, ws, scene: dict):
        self.ws = ws
        self.sent: dict[int, float] = {}  # camera id -> when it was sent
        self.eye, target = np.array(scene["camera"]["eye"]), np.array(scene["camera"]["look_at"])
        self.forward = (target - self.eye) / np.linalg.norm(target - self.eye)

    async def frame(self) -> dict:
        """The next frame's description (its JPEG read and dropped)."""
        while (meta := json.loads(await self.ws.recv()))["type"] != "frame":
            if meta["type"] == "error":
                raise RuntimeError(meta["message"])
        await self.ws.recv()  # the JPEG
        return meta

    async def camera(self, k: int, offset: float) -> None:
        """Camera ``k``: ``offset`` scene units ahead of the scene's own."""
        self.sent[k] = time.perf_counter()
        position = self.eye + offset * self.forward
        message = {"type": "camera", "eye": list(position), "look_at": list(position + self.forward), "id": k}
        await self.ws.send(json.dumps(message))

    async def until_final(self) -> dict:
        while not (meta := await self.frame())["final"]:
            pass
        return meta

    async def held_key(self, messages: int) -> None:
        """A camera message every 1/RATE s, as a held key sends them."""
        for k in range(messages):
            await self.camera(k, 0.03 * k)
            await asyncio.sleep(1 / RATE)

    async def walk(self, messages: int, figures: WalkFigures) -> None:
        """Walk frames read as they come while the key is held."""
        walker = asyncio.create_task(self.held_key(messages))
        clock = time.perf_counter()
        while not walker.done() or figures.frames == 0:
            try:
                meta = await asyncio.wait_for(self.frame(), 5)
            except TimeoutError:
                break
            if meta["phase"] != "walk" or meta["camera_id"] is None:
                continue
            figures.frames += 1
            figures.latencies_ms.append((time.perf_counter() - self.sent[meta["camera_id"]]) * 1000)
            figures.render_ms.append(meta["render_ms"])
            figures.scales.append(meta["scale"])
            figures.pixels.append(meta["width"] * meta["height"])
        figures.seconds = time.perf_counter() - clock
        await walker

    async def step(self, k: int, offset: float, figures: WalkFigures) -> None:
        """One camera message from rest: its first frame, its full-size painting, its refined one."""
        await self.camera(k, offset)
        while (meta := await self.frame())["camera_id"] != k:
            pass
        figures.step_ms.append((time.perf_counter() - self.sent[k]) * 1000)
        while meta["phase"] != "refine":
            meta = await self.frame()
        figures.full_ms.append((time.perf_counter() - self.sent[k]) * 1000)
        while not meta["final"]:
            meta = await self.frame()
        figures.final_ms.append((time.perf_counter() - self.sent[k]) * 1000)


async def _walk(url: str, scene: dict, width: int, height: int, temporal: bool, seconds: float, steps: int):
    figures = WalkFigures(0, seconds, [], [], [], [], [], [], [])
    async with websockets.connect(url, max_size=None) as ws:
        walker = _Walker(ws, scene)
        await ws.send(json.dumps({"type": "hello", "scene": scene["name"], "width": width, "height": height}))
        await ws.send(json.dumps({"type": "mode", "temporal": temporal}))
        await walker.until_final()
        # ---- walk: a camera message every 1/RATE s, frames read as they come ----
        messages = int(seconds * RATE)
        await walker.walk(messages, figures)
        await walker.until_final()
        # ---- single steps from rest ----
        for step in range(steps):
            await walker.step(messages + step, 0.03 * messages - 0.05 * (step + 1), figures)
    return figures


def _alone_ms(scene, width: int, height: int, params: PaintParams, temporal: bool, repeats: int = 7) -> float:
    """The painting a full-size walk frame needs, timed in this process without the service."""
    previous = paint(scene, scene.camera, width, height, params).state if temporal else None
    frame_params = replace(params, iterations=1) if temporal else params
    times = []
    for _ in range(repeats):
        clock = time.perf_counter()
        paint(scene, scene.camera, width, height, frame_params, previous=previous)
        times.append((time.perf_counter() - clock) * 1000)
    return statistics.median(times)


REST_LOAD: dict[str, Any] = {"width": 1280, "height": 720, "paint": {"spp": 4}}


class _Load:
    done = 0


@contextlib.contextmanager
def _rest_load(url: str, scene_name: str, on: bool):
    """A REST caller asking for large paintings back to back while the walk runs (when ``on``)."""
    load, stop = _Load(), threading.Event()

    body = {"scene": scene_name, **REST_LOAD}

    def call():
        while not stop.is_set():
            answer = request(f"{url}/api/render", body, timeout=300)
            if answer.status != 200:
                raise RuntimeError(f"REST load: {answer.status} {answer.body[:200].decode(errors='replace')}")
            load.done += 1

    caller = threading.Thread(target=call, daemon=True)
    if on:
        caller.start()
    try:
        yield load
    finally:
        stop.set()
        if on:
            caller.join()


# 1441 frames: longer than any walk, within the default RCP_VIDEO_DISK_BYTES
VIDEO_LOAD = {"width": 640, "height": 360, "fps": 24, "seconds": 60}


@dataclass
class VideoLoad:
    """A video job's pace: frames a second alone (before the walk) and while the walk runs (NaN when off)."""

    alone_fps: float = float("nan")
    walking_fps: float = float("nan")


def _video_path(scene: dict) -> dict:
    """A path from the scene's camera 10 units towards its target, over ``VIDEO_LOAD["seconds"]``."""
    eye, target = np.array(scene["camera"]["eye"]), np.array(scene["camera"]["look_at"])
    end = eye + 10 * (target - eye) / np.linalg.norm(target - eye)
    return {
        "fps": VIDEO_LOAD["fps"],
        "keyframes": [
            {"t": 0, "eye": list(eye), "look_at": list(target)},
            {"t": VIDEO_LOAD["seconds"], "eye": list(end), "look_at": list(target)},
        ],
    }


@contextlib.contextmanager
def _video_load(url: str, scene: dict, on: bool, seconds: float):
    """A video job painting on the server while the walk runs (when ``on``): submitted over ``POST /api/videos``,
    timed ``seconds`` alone once it paints, timed again over the walk, cancelled at the end."""
    load = VideoLoad()
    if not on:
        yield load
        return
    body = {"scene": scene["name"], "width": VIDEO_LOAD["width"], "height": VIDEO_LOAD["height"]}
    answer = request(f"{url}/api/videos", {**body, "path": _video_path(scene)})
    if answer.status != 202:
        raise RuntimeError(f"video load: {answer.status} {answer.body[:200].decode(errors='replace')}")
    status_url = f"{url}/api/videos/{json.loads(answer.body)['id']}"

    def progress() -> tuple[float, int]:
        status = get_json(status_url)
        if status["state"] != "running":
            raise RuntimeError(f"video load: {status['state']} ({status['message']})")
        return time.perf_counter(), status["done_frames"]

    deadline = time.monotonic() + 120
    while (start := progress())[1] == 0:  # its first frame painted: the kernels and the BVH are warm
        if time.monotonic() > deadline:
            raise RuntimeError("video load: no frame painted in 120 s")
        time.sleep(0.05)
    time.sleep(seconds)
    before = progress()
    load.alone_fps = (before[1] - start[1]) / (before[0] - start[0])
    try:
        yield load
        after = progress()
        load.walking_fps = (after[1] - before[1]) / (after[0] - before[0])
    finally:
        request(status_url, method="DELETE")
        while get_json(status_url)["state"] == "running":  # stopped within a tile
            time.sleep(0.05)


def _row(
    f: WalkFigures, width: int, height: int, temporal: bool, alone: float, rest_renders: int, video: VideoLoad
) -> dict:
    """One mode's figures, as ``rcp bench latency`` prints and returns them."""
    side = (statistics.median(f.pixels) / (width * height)) ** 0.5 if f.pixels else 0.0
    row = {
        "width": width,
        "height": height,
        "temporal": temporal,
        "alone_ms": round(alone, 1),
        "fps": round(f.fps, 1),
        "walk_size": f"{round(width * side)}x{round(height * side)}",
        "latency_p50_ms": round(percentile(f.latencies_ms, 50), 1),
        "latency_p95_ms": round(percentile(f.latencies_ms, 95), 1),
        "render_p50_ms": round(percentile(f.render_ms, 50), 1),
        "step_p50_ms": round(percentile(f.step_ms, 50), 1),
        "full_p50_ms": round(percentile(f.full_ms, 50), 1),
        "full_p95_ms": round(percentile(f.full_ms, 95), 1),
        "final_p50_ms": round(percentile(f.final_ms, 50), 1),
        "final_p95_ms": round(percentile(f.final_ms, 95), 1),
        "rest_renders": rest_renders,
        "video_alone_fps": round(video.alone_fps, 2),
        "video_walking_fps": round(video.walking_fps, 2),
    }
    return row


def _notes(rows: list[dict], width: int, height: int, seconds: float) -> None:
    """What ``rcp bench latency``'s columns mean, printed under them."""
    print(
        f"window {width}x{height}. alone: one {width // 2}x{height // 2} walk frame's painting in this process "
        "(per-frame: all iterations; temporal: one from the last frame). walk size: the median walk frame. "
        "latency: camera message sent -> its frame received, while walking. render: the server's painting "
        "time per walk frame. step: one camera message from rest -> its first frame; full: -> its painting "
        f"at {width}x{height}; final: -> the refined one (4 spp or more). +REST: meanwhile a REST caller keeps "
        f"asking for {REST_LOAD['width']}x{REST_LOAD['height']} paintings at {REST_LOAD['paint']['spp']} spp, "
        f"one after another ({sum(r['rest_renders'] for r in rows)} done)."
    )
    video = rows[-1]
    print(
        f"+video: meanwhile a video job (POST /api/videos, {VIDEO_LOAD['width']}x{VIDEO_LOAD['height']}, the "
        f"scene's painting, every frame from the canvas) paints on the same tile pool: "
        f"{video['video_alone_fps']:.2f} frames/s alone ({seconds:.0f} s before the walk), "
        f"{video['video_walking_fps']:.2f} frames/s during the walk and its steps; then it is cancelled."
    )


def latency(scene_name: str, seconds: float, steps: int) -> dict:
    with BackgroundServer() as server:
        # the server's scenes folder, loaded again here for the paintings timed alone
        scene = load_scene(scene_name, server.settings.scenes)
        info = next(s for s in get_json(f"{server.url}/api/scenes") if s["name"] == scene_name)
        params = scene.paint
        print(
            f"rcp bench latency: scene {scene_name}, {server.settings.threads} threads, camera messages at "
            f"{RATE:.0f} Hz for {seconds:.0f} s, then {steps} single steps from rest; frame budget "
            f"{server.settings.frame_ms:.0f} ms"
        )
        header = (
            f"{'mode':>15} | {'alone ms':>8} | {'fps':>5} {'walk size':>9} {'latency p50':>11} {'p95':>6} "
            f"{'render p50':>10} | {'step p50':>8} {'full p50':>8} {'p95':>6} {'final p50':>9} {'p95':>6}"
        )
        print(header)
        print("-" * len(header))
        rows = []
        width, height = WINDOW
        # the last two: REST renders, then a video job, compete for the cores
        cases = [(False, None), (True, None), (False, "REST"), (False, "video")]
        for temporal, busy in cases:
            alone = _alone_ms(scene, width // 2, height // 2, params, temporal)
            with (
                _rest_load(server.url, scene_name, busy == "REST") as load,
                _video_load(server.url, info, busy == "video", seconds) as video,
            ):
                f = asyncio.run(_walk(server.ws_url, info, width, height, temporal, seconds, steps))
            row = _row(f, width, height, temporal, alone, load.done if busy == "REST" else 0, video)
            rows.append(row)
            mode = ("temporal" if temporal else "per-frame") + (f"+{busy}" if busy else "")
            print(
                f"{mode:>15} | {alone:8.1f} | {f.fps:5.1f} {row['walk_size']:>9} {row['latency_p50_ms']:11.1f} "
                f"{row['latency_p95_ms']:6.1f} {row['render_p50_ms']:10.1f} | {row['step_p50_ms']:8.1f} "
                f"{row['full_p50_ms']:8.1f} {row['full_p95_ms']:6.1f} {row['final_p50_ms']:9.1f} "
                f"{row['final_p95_ms']:6.1f}"
            )
        _notes(rows, width, height, seconds)
        return {"scene": scene_name, "threads": server.settings.threads, "rows": rows}
