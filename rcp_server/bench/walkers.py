"""``rcp bench walkers N``: N walkers at once against a real ``rcp serve`` (its threads, or Ray with ``--ray``).

Each walker says hello at ``width x height`` and moves its camera again as soon as a frame of its last camera
arrives, for ``seconds``: what it gets is as many frames as the server gives it. Printed per walker: frames a
second, the mean frame size, and the 95th percentile of the latency from a camera message to the first frame
that shows it; a walker the server has no room for prints its one-line refusal. Then the CPU seconds spent
in the server's process against those its Ray workers report (``/api/health``), over the same window.
"""

from __future__ import annotations

import asyncio
import json
import os
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import websockets

from ..service.loopback import get_json, rcp_serve
from .latency import percentile

WARM_S = 3.0  # walking before the window opens (each walker's actor starts, its planner finds its size)


@dataclass
class Walker:
    frames: list[float] = field(default_factory=list)  # arrival times inside the window
    pixels: list[int] = field(default_factory=list)
    latencies_ms: list[float] = field(default_factory=list)
    refused: str | None = None


async def _walk(url: str, scene: dict, width: int, height: int, start: float, end: float) -> Walker:
    walker = Walker()
    eye, target = np.array(scene["camera"]["eye"]), np.array(scene["camera"]["look_at"])
    async with websockets.connect(url, max_size=None) as ws:
        await ws.send(json.dumps({"type": "hello", "scene": scene["name"], "width": width, "height": height}))
        sent: dict[int, float] = {}
        k = 0
        while time.perf_counter() < end:
            try:
                meta = json.loads(await asyncio.wait_for(ws.recv(), max(0.1, end - time.perf_counter())))
            except TimeoutError:
                break
            if meta["type"] == "error":
                walker.refused = meta["message"]
                return walker
            if meta["type"] != "frame":
                continue
            await ws.recv()  # the JPEG
            now = time.perf_counter()
            if now >= start:
                walker.frames.append(now)
                walker.pixels.append(meta["width"] * meta["height"])
                if meta["camera_id"] in sent:
                    walker.latencies_ms.append((now - sent.pop(meta["camera_id"])) * 1000)
            if meta["camera_id"] is None or meta["camera_id"] == k:  # the last camera shown: move again
                k += 1
                angle = 0.02 * k
                turn = np.array([np.sin(angle), 0.0, np.cos(angle)]) * np.linalg.norm(eye - target)
                message = {"type": "camera", "eye": list(target + turn), "look_at": list(target), "id": k}
                sent[k] = time.perf_counter()
                await ws.send(json.dumps(message))
    return walker


def _cpu_s(pid: int) -> float:
    """CPU seconds (user and system) process ``pid`` has spent, from ``/proc/<pid>/stat``."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def _all(url: str, scene: dict, n: int, width: int, height: int, seconds: float) -> list[Walker]:
    start = time.perf_counter() + WARM_S
    return list(await asyncio.gather(*(_walk(url, scene, width, height, start, start + seconds) for _ in range(n))))


def bench_walkers(n: int, address: str | None, scene_name: str, width: int, height: int, seconds: float) -> None:
    settings = {"walk_width": str(width), "walk_height": str(height), "max_sessions": str(max(8, n))}
    if address:
        settings["ray_address"] = address
    with tempfile.TemporaryDirectory(prefix="rcp-bench-walkers-") as folder, rcp_serve(Path(folder), **settings) as srv:
        scenes = {s["name"]: s for s in get_json(f"{srv.url}/api/scenes")}
        scene = scenes[scene_name]
        before = get_json(f"{srv.url}/api/health").get("walks", {})
        cpu = _cpu_s(srv.process.pid)
        walkers = asyncio.run(_all(srv.ws_url, scene, n, width, height, seconds))
        server_cpu = _cpu_s(srv.process.pid) - cpu
        after = get_json(f"{srv.url}/api/health").get("walks", {})
    where = f"Ray at {address}" if address else "the server's threads"
    print(f"{n} walkers of {scene_name!r} at {width}x{height}, painted on {where}, {seconds:g} s after {WARM_S:g} s")
    print(f"{'walker':>6} {'fps':>6} {'size':>10} {'p95 ms':>7}")
    for k, walker in enumerate(walkers):
        if walker.refused is not None:
            print(f"{k:>6} refused: {walker.refused}")
            continue
        fps = len(walker.frames) / seconds
        side = np.sqrt(np.mean(walker.pixels) * height / width) if walker.pixels else 0.0
        size = f"{side * width / height:.0f}x{side:.0f}"
        p95 = percentile(walker.latencies_ms, 95) if walker.latencies_ms else float("nan")
        print(f"{k:>6} {fps:6.1f} {size:>10} {p95:7.0f}")
    worker_cpu = after.get("worker_cpu_s", 0.0) - before.get("worker_cpu_s", 0.0)
    frames = after.get("frames", 0) - before.get("frames", 0)
    print(
        f"CPU over the run (warm-up included): server {server_cpu:.1f} s, Ray workers {worker_cpu:.1f} s "
        f"({frames} frames on Ray; the workers' share {worker_cpu / max(server_cpu + worker_cpu, 1e-9):.0%})"
    )


def bench_crew(nodes: int, scene_name: str, width: int, height: int, seconds: float) -> None:
    """One walker's frames in bands over a crew on ``nodes`` nodes of Ray's multi-node test cluster (one CPU each,
    each its own raylet), through the server's driver process, against the same frames on this machine's threads:
    frames a second, the frame's size, p95 latency, and the round trip beyond the slowest band's painting."""
    from ray.cluster_utils import Cluster

    from ..cluster.admission import Target
    from ..cluster.remote import RemoteRay, RemoteWalks
    from ..cluster.walks import NoRoom
    from ..painting.loop import paint
    from ..scene.scenefile import load_scene
    from ..util import images

    scene = load_scene(scene_name)
    params = replace(scene.paint, spp=1)
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    for _ in range(nodes - 1):
        cluster.add_node(num_cpus=1)
    driver = RemoteRay(cluster.address, Target(0.01, width, height), 30)
    try:
        driver.start(120)
        walks = RemoteWalks(driver, 1, 30)
        walks.calibrate(scene, params)
        walks.admit("crew", params, scene)
        times: list[tuple[float, float, int, float]] = []  # (round trip, slowest band's painting, bands, free)
        deadline, end, k = time.monotonic() + 120, None, 0
        while end is None or time.monotonic() < end:
            k += 1
            camera = scene.camera.moved(eye=tuple(np.asarray(scene.camera.eye) + (0.01 * k, 0.0, 0.0)))
            try:
                clock, sent = time.perf_counter(), time.time()
                painted = walks.paint("crew", scene, camera, width, height, params, 0.0, 80, k, None)
                back = time.time()
            except NoRoom:  # the crew is starting
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
                continue
            bands = max(1, len(painted.bands))
            if end is None and (bands == nodes or time.monotonic() > deadline):
                end = time.monotonic() + seconds
            elif end is not None:
                times.append((time.perf_counter() - clock, painted.paint_s, bands, _free(painted.bands, sent, back)))
    finally:
        driver.close()
        cluster.shutdown()
    here: list[float] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        clock = time.perf_counter()
        images.encode(paint(scene, scene.camera, width, height, params, threads=nodes).image, "JPEG", 80)
        here.append(time.perf_counter() - clock)
    print(f"one walker of {scene_name!r} at {width}x{height}, {params.iterations} iterations, {seconds:g} s each")
    _report(times, here, nodes, seconds)


def _report(times: list[tuple[float, float, int, float]], here: list[float], nodes: int, seconds: float) -> None:
    """The crew's frames (round trip, slowest band's painting, bands, Ray's part) against the threads' ``here``."""
    trips = np.array([t for t, _, _, _ in times])
    overhead = np.array([t - p for t, p, _, _ in times])
    free = np.median([f for _, _, _, f in times]) * 1e3
    print(f"{'where':>28} {'fps':>6} {'p95 ms':>7} {'overhead ms':>12} {'of it Ray':>10}")
    crew = f"a crew on {nodes} nodes ({times[-1][2] if times else 0} bands)"
    p95, median = np.percentile(trips, 95) * 1e3, np.median(overhead) * 1e3
    print(f"{crew:>28} {len(trips) / seconds:6.1f} {p95:7.1f} {median:12.1f} {free:10.1f}")
    threads = f"{nodes} threads here"
    print(f"{threads:>28} {len(here) / seconds:6.1f} {np.percentile(here, 95) * 1e3:7.1f} {'':>12} {'':>10}")
    print(
        "overhead: the round trip beyond the slowest band's painting (medians); of it Ray: the first band's way out "
        "and the last band's way back, and the bands' time on their workers beyond painting (not the time a band "
        f"waits for a core: here {nodes} nodes share this machine's {os.cpu_count()} cores)"
    )


def _free(bands, sent: float, back: float) -> float:
    """A frame's round trip beyond painting, without a band's wait for a core of this machine: from the call to
    the first band's start, from the last band's end to the answer, and each band's longest time on its worker
    beyond its painting (the workers' clocks are this machine's)."""
    if not bands:
        return 0.0
    first = min(band.span[0] for band in bands)
    last = max(band.span[1] for band in bands)
    beyond = max(band.span[1] - band.span[0] - band.paint_s for band in bands)
    return (first - sent) + (back - last) + beyond
