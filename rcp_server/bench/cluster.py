"""``rcp bench cluster``: the same camera path painted by this machine's threads and by Ray actors, and a
model of N machines from what it measures.

On this machine, Ray (a local runtime, or ``--ray ADDRESS``) paints the path per frame and temporally; each
run is timed against the threaded run of the same frames (the overhead: processes, the object store,
serialization). It measures the bytes each frame moves (the request: camera, time and settings, pickled; the
answer: the frame as uint8), the time to the first frame (Ray started, the actors warm: the scene in the
object store and a BVH built in each), and a Ray call's round trip; and one large painting (twice the size
each way, 4 spp) in bands, as the server paints a large REST render, against the threads.

The model (printed with its inputs): N machines of ``cores`` cores each, joined to the encoder by ``gbps``.

* per frame: a frame takes ``T`` seconds on one core; N machines finish ``N cores / T`` frames a second,
  unless the link carries fewer (``gbps / bytes``). Efficiency = achieved / ideal, times this machine's
  measured Ray overhead.
* temporal: every frame is split into ``N cores`` bands that must all arrive before the frame is encoded;
  a frame costs ``T / (N cores)`` of painting plus one round trip and its bytes over the link, which the
  two frames in flight overlap with painting only when painting is the longer part.
"""

from __future__ import annotations

import pickle
import time
from dataclasses import replace

import numpy as np

from ..cluster.admission import Target
from ..cluster.connection import Connection
from ..cluster.painter import RayPainter, connect
from ..cluster.walks import NoRoom, Walks
from ..media.camerapath import parse_path
from ..painting.loop import default_threads, paint
from ..painting.sequence import frame_params, paint_sequence
from ..scene.scenefile import load_scene
from ..service.planner import WALK_QUALITY
from ..util.images import encode as encode_image
from .walkmodel import Measured, banded, crew, walker_cores, walkers_held


def walk_path(scene, seconds: float, fps: float) -> dict:
    """A path around the scene's own camera: a quarter orbit about its look-at point, then in towards it."""
    eye, target = np.asarray(scene.camera.eye), np.asarray(scene.camera.look_at)
    offset = eye - target
    turn = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # a quarter turn about +y
    keys = [eye, target + (offset + turn @ offset) / 2, target + 0.7 * (turn @ offset)]
    times = np.linspace(0.0, seconds, len(keys))
    keyframes = [
        {"t": float(t), "eye": k.tolist(), "look_at": target.tolist()} for t, k in zip(times, keys, strict=True)
    ]
    return {"fps": fps, "keyframes": keyframes}


WALK_SIZES = ((640, 360), (1280, 720))  # the walkers' model's frame sizes
NODES = (1, 4, 16, 64)  # the KubeRay clusters modelled, in two-core nodes
NODE_CORES = 2
WALK_FPS = 20.0
BANDED = ((1280, 720), 30.0, 8)  # one walker's frame in bands: size, frames a second, nodes
EFFICIENCY = 0.8  # the per-node efficiency a crew is to keep
WALK_FRAMES = 5  # frames measured of each size and mode


def measure_walks(scene, address: str | None) -> Measured:
    """A walk actor's figures on Ray (joined already): its frame's and ray's CPU (calibrated at the model's
    first size, as the server does), and walk frames of each size, per frame and temporal, timed from here."""
    params = replace(scene.paint, spp=1)  # a walk frame's
    walks = Walks(Connection(address), Target(1.0, 1, 1), 30)  # a target any cluster has room for: one walker
    frame_s, ray_s = walks.calibrate(scene, params, WALK_SIZES[0])
    walks.admit("bench", params, scene)
    overheads, server, jpeg, encode = [], [], {}, {}
    try:
        for size in WALK_SIZES:
            deadline = time.monotonic() + 120
            while True:  # its crew built and warm
                try:
                    walks.paint("bench", scene, scene.camera, *size, params, 0.0, WALK_QUALITY, 0, None)
                    break
                except NoRoom:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.1)
            sizes = []
            for k in range(1, WALK_FRAMES + 1):
                for temporal in (False, True):
                    p = replace(params, iterations=1) if temporal else params
                    clock, cpu = time.perf_counter(), time.process_time()
                    painted = walks.paint(
                        "bench",
                        scene,
                        scene.camera,
                        *size,
                        p,
                        0.0,
                        WALK_QUALITY,
                        2 * k + temporal,
                        2 * k if temporal else None,
                    )
                    server.append(time.process_time() - cpu)
                    overheads.append(time.perf_counter() - clock - painted.paint_s)
                    sizes.append(len(painted.jpeg) + sum(len(band.jpeg) for band in painted.bands))
            jpeg[size] = int(np.median(sizes))
            image = paint(scene, scene.camera, *size, replace(params, iterations=1), threads=1).image
            clock = time.perf_counter()
            encode_image(image, "JPEG", WALK_QUALITY)
            encode[size] = time.perf_counter() - clock
    finally:
        walks.close()
    return Measured(
        frame_s, ray_s, float(np.median(overheads)), float(np.median(server)), jpeg, encode, params.iterations
    )


def print_walk_model(m: Measured, gbps: float, server_cores: int) -> None:
    print(
        f"\nwalkers, measured on Ray: {m.frame_s * 1e3:.2f} ms of CPU a frame and {m.ray_s * 1e9:.1f} ns a ray "
        f"(a pixel through one iteration, on one core); a frame's round trip beyond its painting "
        f"{m.overhead_s * 1e3:.1f} ms; {m.server_s * 1e3:.2f} ms of the server's CPU a frame; JPEG "
        + ", ".join(f"{w}x{h} {b / 1e3:.1f} kB" for (w, h), b in m.jpeg_bytes.items())
        + "; encoding here "
        + ", ".join(f"{w}x{h} {s * 1e3:.1f} ms" for (w, h), s in m.encode_s.items())
    )
    print(
        f"model: {WALK_FPS:g} fps, 1 sample a pixel, {m.iterations} iterations a frame (temporal: 1); nodes of "
        f"{NODE_CORES} cores; a server of {server_cores} cores on {gbps:g} Gbit/s"
    )
    print(
        "each cell: walkers held (cores a walker takes, nodes a walker's frames take: more than 1 in bands, the bound)"
    )
    header = "".join(f" {f'{w}x{h} {mode}':>28}" for w, h in WALK_SIZES for mode in ("per frame", "temporal"))
    print(f"{'nodes':>5}{header}")
    for nodes in NODES:
        cells = []
        for size in WALK_SIZES:
            for iterations in (m.iterations, 1):
                held, bound, span = walkers_held(m, size, WALK_FPS, iterations, nodes, NODE_CORES, server_cores, gbps)
                cores = walker_cores(m, size, WALK_FPS, iterations)
                cells.append(f"{held:>4} ({cores:5.2f} c, {span} n, {bound:>7})")
        print(f"{nodes:>5}" + "".join(f" {c:>28}" for c in cells))
    size, fps, nodes = BANDED
    print(
        f"one walker at {size[0]}x{size[1]} in bands over {nodes} nodes of {NODE_CORES} cores (a band a node, each "
        f"encoded on its node and forwarded as it is; {m.overhead_s * 1e3:.1f} ms a frame beyond its painting):"
    )
    for name, iterations in (("per frame", m.iterations), ("temporal", 1)):
        # the fewest nodes that keep up (as the crew uses no more nodes than help), else all of them
        used = next((n for n in range(1, nodes + 1) if crew(m, size, n, NODE_CORES, iterations)[0] >= fps), nodes)
        rate, latency, efficiency = crew(m, size, used, NODE_CORES, iterations)
        verdict = "holds" if rate >= fps and efficiency >= EFFICIENCY else "falls short of"
        print(
            f"  {name:>9} on {used} nodes: {rate:5.1f} fps, {latency * 1e3:.0f} ms a frame, per-node efficiency "
            f"{efficiency:.2f} ({verdict} {fps:g} fps at {EFFICIENCY:g})"
        )
    print("the same, gathered on one machine (earlier models):")
    for encoders in (0, 2):
        where = "encoded by 2 worker cores in turn" if encoders else "gathered and encoded by the server"
        for name, iterations in (("per frame", m.iterations), ("temporal", 1)):
            bands = nodes * NODE_CORES - encoders
            rate, latency, bound = banded(m, size, bands, iterations, gbps, encoders)
            verdict = "holds" if rate >= fps else "falls short of"
            print(
                f"  {name:>9}, {bands} bands {where}: {rate:5.1f} fps ({verdict} {fps:g}; bound by {bound}), "
                f"{latency * 1e3:.0f} ms a frame"
            )


def bench_cluster(
    scene_name: str,
    width: int,
    height: int,
    frames: int,
    address: str | None,
    gbps: float,
    cores: int,
    walkers_only: bool = False,
    server_cores: int = 4,
    overhead_ms: float | None = None,
) -> None:
    """``overhead_ms``: a frame's round trip beyond its painting as measured elsewhere (``rcp bench walkers --crew``
    on the test cluster), in place of the one measured here."""
    scene = load_scene(scene_name)

    def taken(m: Measured) -> Measured:
        return m if overhead_ms is None else replace(m, overhead_s=overhead_ms / 1e3)

    if walkers_only:
        started = connect(address, num_cpus=None if address else default_threads())
        try:
            print_walk_model(taken(measure_walks(scene, address)), gbps, server_cores)
        finally:
            if started:
                import ray

                ray.shutdown()
        return
    measured = _measure_on_ray(scene, scene_name, width, height, frames, address)
    _print_films_model(measured, cores, gbps)
    print_walk_model(taken(measured["walks"]), gbps, server_cores)


def _threaded(scene, shots, params, width: int, height: int, threads: int, temporal) -> tuple[float, list]:
    """Seconds and paintings of ``shots`` on this machine's threads (``temporal`` False: the first shot alone)."""

    def paint_frame(camera, scene_time, p, previous):
        return paint(scene, camera, width, height, p, time=scene_time, previous=previous, threads=threads)

    clock = time.perf_counter()
    out = list(paint_sequence(paint_frame, shots if temporal is not False else shots[:1], params, temporal or None))
    return time.perf_counter() - clock, out


def _measure_on_ray(scene, scene_name: str, width: int, height: int, frames: int, address: str | None) -> dict:
    """Films, one large painting and a panorama on Ray against the threads (printed as measured), and the
    walkers' figures: what the models are made from."""
    params = scene.paint
    fps = 24.0
    path = parse_path(walk_path(scene, (frames - 1) / fps, fps)).resolve(scene.camera)
    shots = list(path.frames())
    threads = default_threads()
    print(
        f"scene {scene_name!r}, {width}x{height}, {len(shots)} frames, {params.spp} spp, {params.iterations} iterations"
    )
    _threaded(scene, shots, params, width, height, threads, False)  # the kernels (and the BVH) before any timing
    clock = time.perf_counter()
    started = connect(address, num_cpus=None if address else threads)
    joined = time.perf_counter() - clock
    painter = RayPainter(address)
    try:
        actors, trip, request = _measure_start(painter, scene, shots, params, width, height, joined)
        rows = _measure_films(painter, scene, shots, params, width, height, threads)
        _measure_large(painter, scene, params, width, height, threads, len(actors))
        pano, pano_ray_s = _measure_panorama(painter, scene, params, height, threads, len(actors))
        painter.crew.close()  # its actors hold every core: the walkers' figures are measured alone
        walk_figures = measure_walks(scene, address)
    finally:
        painter.close()
        if started:
            import ray

            ray.shutdown()
    return {
        "params": params,
        "shots": shots,
        "actors": len(actors),
        "rows": rows,
        "trip": trip,
        "request": request,
        "pano": pano,
        "pano_ray_s": pano_ray_s,
        "walks": walk_figures,
        "size": (width, height),
    }


def _measure_start(painter, scene, shots, params, width: int, height: int, joined: float) -> tuple[list, float, int]:
    """Warm ``painter``'s actors, time the first frame and a Ray call's round trip (median of 50), count a
    frame's bytes each way, and print them; the actors, the round trip in seconds and a request's bytes."""
    clock = time.perf_counter()
    actors = painter.warm(scene)
    import ray

    warm = time.perf_counter() - clock
    clock = time.perf_counter()
    first = next(painter.images(scene, shots[:1], width, height, params))
    first_frame = time.perf_counter() - clock
    trips = []
    for _ in range(50):
        clock = time.perf_counter()
        ray.get(actors[0].pid.remote())
        trips.append(time.perf_counter() - clock)
    trip = float(np.median(trips))
    request = len(pickle.dumps((shots[1].camera, shots[1].scene_time, frame_params(params, None, 1))))
    answer = first.nbytes
    print(f"Ray: joined in {joined:.1f} s, {len(actors)} actors warm in {warm:.1f} s (scene put once, BVH each)")
    total = joined + warm + first_frame
    print(f"time to the first frame: {first_frame * 1000:.0f} ms after warm-up ({total:.1f} s from nothing)")
    print(f"a Ray call's round trip: {trip * 1000:.2f} ms (median of 50)")
    print(f"bytes per frame: {request:,} out (camera, time, settings), {answer:,} back (uint8 frame)")
    return actors, trip, request


def _measure_films(painter, scene, shots, params, width: int, height: int, threads: int) -> list:
    """The film painted per frame and temporally (K=1) on the threads and on Ray, printed as measured; a row
    (name, threads' seconds, Ray's seconds, pixel-identical) each."""
    rows = []
    for name, temporal in (("per frame", None), ("temporal K=1", 1)):
        here_s, here = _threaded(scene, shots, params, width, height, threads, temporal)
        clock = time.perf_counter()
        there = list(painter.images(scene, shots, width, height, params, temporal))
        ray_s = time.perf_counter() - clock
        same = all(np.array_equal(a, b) for a, b in zip(there, (_u8(i) for i in here), strict=True))
        rows.append((name, here_s, ray_s, same))
        print(
            f"{name:>13}: threads {here_s:6.2f} s ({here_s / len(shots) * 1000:6.1f} ms/frame), "
            f"Ray {ray_s:6.2f} s ({ray_s / len(shots) * 1000:6.1f} ms/frame), "
            f"overhead {ray_s / here_s:4.2f}x, pixel-identical: {same}"
        )
    return rows


def _measure_large(painter, scene, params, width: int, height: int, threads: int, actors: int) -> None:
    """One painting twice the film's size at 4 spp, as a REST render over RCP_RAY_MIN_WORK asks (a band of rows
    per actor), on the threads and on Ray; printed."""
    big, large = (2 * width, 2 * height), replace(params, spp=4)
    clock = time.perf_counter()
    here = _u8(paint(scene, scene.camera, *big, large, threads=threads).image)
    here_s = time.perf_counter() - clock
    clock = time.perf_counter()
    there_one = painter.render(scene, scene.camera, *big, large)
    ray_s = time.perf_counter() - clock
    print(
        f"one {big[0]}x{big[1]} painting at 4 spp: threads {here_s:.2f} s, "
        f"Ray in {actors} bands {ray_s:.2f} s, "
        f"overhead {ray_s / here_s:4.2f}x, pixel-identical: {np.array_equal(here, there_one)}"
    )


def _measure_panorama(painter, scene, params, height: int, threads: int, actors: int) -> tuple[tuple[int, int], float]:
    """A panorama (equirect, an eye's image twice as wide as high) on the threads and in Ray's bands, printed;
    its size and Ray's seconds."""
    pano_camera, pano = scene.camera.moved(projection="equirect"), (4 * height, 2 * height)
    clock = time.perf_counter()
    here = _u8(paint(scene, pano_camera, *pano, params, threads=threads).image)
    pano_here_s = time.perf_counter() - clock
    clock = time.perf_counter()
    there_one = painter.render(scene, pano_camera, *pano, params)
    pano_ray_s = time.perf_counter() - clock
    print(
        f"one {pano[0]}x{pano[1]} panorama: threads {pano_here_s:.2f} s, Ray in {actors} bands "
        f"{pano_ray_s:.2f} s, pixel-identical: {np.array_equal(here, there_one)}"
    )
    return pano, pano_ray_s


def _print_films_model(measured: dict, cores: int, gbps: float) -> None:
    """The model of N machines painting films and a panorama, from :func:`_measure_on_ray`'s figures."""
    params, shots, actors, rows = measured["params"], measured["shots"], measured["actors"], measured["rows"]
    trip, request, pano, pano_ray_s = measured["trip"], measured["request"], measured["pano"], measured["pano_ray_s"]
    width, height = measured["size"]
    # ---- the model: core-seconds per ray x iteration from the Ray runs, applied to a target workload ----
    rays = width * height * params.spp
    core_s = {name: ray_s / len(shots) * actors for name, _, ray_s, _ in rows}
    per_ray = {
        "per frame": core_s["per frame"] / (rays * params.iterations),
        "temporal K=1": core_s["temporal K=1"] / rays,  # one iteration a frame (after the first)
    }
    w, h, spp, iterations = 1920, 1080, 8, params.iterations
    link = gbps * 1e9 / 8  # bytes a second
    frame_bytes = w * h * 3
    paint_frame = per_ray["per frame"] * w * h * spp * iterations  # core-seconds
    paint_temporal = per_ray["temporal K=1"] * w * h * spp
    print(
        f"\nmodel: {w}x{h}, {spp} spp, {iterations} iterations per frame (temporal: 1 a frame); machines of "
        f"{cores} cores, {gbps:g} Gbit/s to the encoder; from the Ray runs: {paint_frame:.0f} core-s a frame, "
        f"{paint_temporal:.1f} core-s a temporal frame, {frame_bytes / 1e6:.1f} MB a frame, {trip * 1000:.1f} ms a call"
    )
    print(f"{'N':>5} {'per-frame fps':>14} {'eff':>5} {'temporal fps':>13} {'eff':>5}")
    for n in (1, 2, 4, 8, 16, 32, 64, 128, 256):
        ideal = n * cores / paint_frame
        achieved = min(ideal, link / (frame_bytes + request))
        bands = n * cores
        t_paint = paint_temporal / bands
        # two frames in flight hide a call's round trip behind painting; the encoder's link moves every byte
        t_frame = max(t_paint, (frame_bytes + request * bands) / link, (t_paint + trip) / 2)
        print(f"{n:>5} {achieved:14.2f} {achieved / ideal:5.2f} {1 / t_frame:13.1f} {t_paint / t_frame:5.2f}")

    # a 4096x2048 panorama at the scene's settings: its core-seconds from the Ray run, a band a core
    pano_core_s = pano_ray_s * actors / (pano[0] * pano[1]) * 4096 * 2048
    print(f"\na 4096x2048 panorama ({params.iterations} iterations, {params.spp} spp): {pano_core_s:.1f} core-s; on")
    for n in (1, 2, 4, 8, 16):
        print(f"{n:>5} machines: {pano_core_s / (n * cores) + 4096 * 2048 * 3 / link + trip:6.2f} s")


def _u8(image):
    from ..util.images import to_uint8

    return to_uint8(image)
