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

from ..cluster.painter import RayPainter, connect
from ..media.camerapath import parse_path
from ..painting.loop import default_threads, paint
from ..painting.sequence import frame_params, paint_sequence
from ..scene.scenefile import load_scene


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


def bench_cluster(
    scene_name: str, width: int, height: int, frames: int, address: str | None, gbps: float, cores: int
) -> None:
    scene = load_scene(scene_name)
    params = scene.paint
    fps = 24.0
    path = parse_path(walk_path(scene, (frames - 1) / fps, fps)).resolve(scene.camera)
    shots = list(path.frames())
    threads = default_threads()
    print(
        f"scene {scene_name!r}, {width}x{height}, {len(shots)} frames, {params.spp} spp, {params.iterations} iterations"
    )

    def threaded(temporal):
        def paint_frame(camera, scene_time, p, previous):
            return paint(scene, camera, width, height, p, time=scene_time, previous=previous, threads=threads)

        clock = time.perf_counter()
        out = list(paint_sequence(paint_frame, shots if temporal is not False else shots[:1], params, temporal or None))
        return time.perf_counter() - clock, out

    threaded(False)  # load the compiled kernels (and the BVH) before anything is timed
    clock = time.perf_counter()
    started = connect(address, num_cpus=None if address else threads)
    joined = time.perf_counter() - clock
    painter = RayPainter(address)
    try:
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
        rows = []
        for name, temporal in (("per frame", None), ("temporal K=1", 1)):
            here_s, here = threaded(temporal)
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
        # one large painting, as a REST render over RCP_RAY_MIN_WORK asks: a band of rows per actor
        big, large = (2 * width, 2 * height), replace(params, spp=4)
        clock = time.perf_counter()
        here = _u8(paint(scene, scene.camera, *big, large, threads=threads).image)
        here_s = time.perf_counter() - clock
        clock = time.perf_counter()
        there_one = painter.render(scene, scene.camera, *big, large)
        ray_s = time.perf_counter() - clock
        print(
            f"one {big[0]}x{big[1]} painting at 4 spp: threads {here_s:.2f} s, "
            f"Ray in {len(actors)} bands {ray_s:.2f} s, "
            f"overhead {ray_s / here_s:4.2f}x, pixel-identical: {np.array_equal(here, there_one)}"
        )
        # a panorama (equirect, an eye's image twice as wide as high), threads against Ray's bands
        pano_camera, pano = scene.camera.moved(projection="equirect"), (4 * height, 2 * height)
        clock = time.perf_counter()
        here = _u8(paint(scene, pano_camera, *pano, params, threads=threads).image)
        pano_here_s = time.perf_counter() - clock
        clock = time.perf_counter()
        there_one = painter.render(scene, pano_camera, *pano, params)
        pano_ray_s = time.perf_counter() - clock
        print(
            f"one {pano[0]}x{pano[1]} panorama: threads {pano_here_s:.2f} s, Ray in {len(actors)} bands "
            f"{pano_ray_s:.2f} s, pixel-identical: {np.array_equal(here, there_one)}"
        )
    finally:
        painter.close()
        if started:
            import ray

            ray.shutdown()

    # ---- the model: core-seconds per ray x iteration from the Ray runs, applied to a target workload ----
    rays = width * height * params.spp
    core_s = {name: ray_s / len(shots) * len(actors) for name, _, ray_s, _ in rows}
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
    pano_core_s = pano_ray_s * len(actors) / (pano[0] * pano[1]) * 4096 * 2048
    print(f"\na 4096x2048 panorama ({params.iterations} iterations, {params.spp} spp): {pano_core_s:.1f} core-s; on")
    for n in (1, 2, 4, 8, 16):
        print(f"{n:>5} machines: {pano_core_s / (n * cores) + 4096 * 2048 * 3 / link + trip:6.2f} s")


def _u8(image):
    from ..util.images import to_uint8

    return to_uint8(image)
