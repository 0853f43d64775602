"""``rcp bench speed``: where an iteration's time goes, per stage in nanoseconds a pixel, and what a whole
painting costs against one pass of Embree alone over the same rays.

Both sides run in one process, interleaved repeat by repeat, with the same rays, tiles and threads,
so the ratio holds on a noisy machine even when the absolute figures move.
"""

from __future__ import annotations

import math
import statistics
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from ..camera.camera import Region
from ..engine.kernels import screencells, visibility
from ..engine.kernels.embree import EmbreexScene, intersect_rays
from ..painting import screen
from ..painting.assign import Rays, assign_cameras, setup_tile
from ..painting.frame import Frame
from ..painting.loop import STAGES, default_threads, paint, tile_rows
from ..scene.scene import Scene
from ..scene.scenefile import load_scene
from ..settings.params import PaintParams


def _embree_alone(query, origins, directions, tiles, pool, passes: int) -> float:
    """Seconds per pass of a bare Embree ``query(origins, directions)`` over the given ray bands, threads as
    in painting (as many passes as the painting has iterations, so both sides of a pair span the same stretch
    of time)."""

    def run(band):
        for _ in range(passes):
            query(origins[band], directions[band])

    clock = time.perf_counter()
    list(pool.map(run, tiles))
    return (time.perf_counter() - clock) / passes


def speed(scene_name: str, width: int, height: int, iterations: int, repeats: int, threads: int | None) -> None:
    """Print where an iteration of the color mapping goes (per stage, nanoseconds a pixel), the screen cells'
    paths, and what a painting costs against embreex and Embree's bare packets over the same rays."""
    scene = load_scene(scene_name)
    threads = threads or default_threads()
    # the color mapping against Embree: what tracing every ray costs beyond the tracing
    params = PaintParams(mapping="color", iterations=iterations, spp=1, lambda_p=float(scene.paint.lambda_p))
    camera = scene.camera
    geometry, tracer = scene.geometry(0.0)
    print(
        f"scene {scene_name!r}: {geometry.face_count} triangles; {width}x{height}, 1 spp, "
        f"{iterations} iterations, color mapping, {threads} threads"
    )
    paint(scene, camera, width, height, params, threads=threads)  # compile kernels, build the BVH
    n, origins, directions, bands = _painted_rays(scene, camera, width, height, params, threads)
    hit_fraction = float((tracer.intersect(origins, directions).face >= 0).mean()) if tracer else 0.0
    if tracer is not None:
        screen.forget()  # a build of its own, timed, the kernels compiled
        _screen_paths(
            Frame.of(scene, 0.0, camera, params, width, height, threads=threads).trace, origins, directions, repeats
        )

    # the two references: embreex (one rtcIntersect1 a ray, from its loop) and Embree's own coherent packets
    # on the same rays, without anything around them (the limit of this machine)
    embreex = EmbreexScene(geometry.triangles) if tracer else None
    scratch = np.empty(n, np.int32)
    queries = {
        "embreex": embreex.bare_query if embreex else None,
        "packets": (lambda o, d: tracer.bare_query(o, d, scratch[: len(o)], width)) if tracer else None,
    }
    painted, stage_sums, alone = _paired_repeats(
        scene, width, height, params, threads, repeats, queries, (origins, directions, bands)
    )
    print(f"rays hitting geometry: {hit_fraction:.0%}")
    _print_stages(painted, stage_sums, n, repeats, threads)
    if tracer is None:
        print("Embree alone: nothing to compare with, this scene has no triangles (every ray sees the sky)")
        return
    _print_against_embree(painted, alone, n, iterations, repeats)
    _own_painting(scene, width, height, replace(scene.paint, iterations=iterations), repeats, threads, alone)


def _painted_rays(scene: Scene, camera, width: int, height: int, params: PaintParams, threads: int):
    """The rays a painted iteration casts (those after the sixth), in the same row bands as the painting: the
    pixel count n, origins and directions ((n, 3) each) and the bands (slices of rows)."""
    region = Region(width, height)
    state = paint(scene, camera, width, height, params, threads=threads).state
    setup = setup_tile(camera, region, params)
    n = region.pixel_count
    rays = Rays.allocate(n, 1)
    assign_cameras(state, setup, params, params.focus(camera), rays)
    bands = [slice(t.y0 * width, (t.y0 + t.height) * width) for t in region.tiles(tile_rows(region, threads))]
    return n, rays.origins, rays.directions, bands


def _paired_repeats(
    scene: Scene, width: int, height: int, params: PaintParams, threads: int, repeats: int, queries: dict, rays
) -> tuple[list[float], dict[str, float], dict[str, list[float]]]:
    """``repeats`` paintings, each followed by every Embree query alone over the same ``rays`` (origins,
    directions, bands) under the same load: seconds per iteration of each painting, its stages' mean thread
    seconds per iteration, and each query's seconds per pass (NaN without a query)."""
    origins, directions, bands = rays
    iterations = params.iterations
    painted, stage_sums = [], dict.fromkeys(STAGES, 0.0)
    alone: dict[str, list[float]] = {name: [] for name in queries}
    with ThreadPoolExecutor(threads) as pool:
        for _ in range(repeats):
            clock = time.perf_counter()
            result = paint(scene, scene.camera, width, height, params, threads=threads)
            painted.append((time.perf_counter() - clock) / iterations)
            for stage in STAGES:
                stage_sums[stage] += result.stage_seconds[stage] / iterations / repeats
            for name, query in queries.items():
                seconds = _embree_alone(query, origins, directions, bands, pool, iterations) if query else math.nan
                alone[name].append(seconds)
    return painted, stage_sums, alone


def _print_stages(painted: list[float], stage_sums: dict[str, float], n: int, repeats: int, threads: int) -> None:
    """Print an iteration's wall time (median) and where its thread time goes, in nanoseconds a pixel."""
    per_iteration = statistics.median(painted)
    thread_total = sum(stage_sums.values())
    print(
        f"one iteration (wall, median of {repeats}): {per_iteration * 1e3:7.2f} ms   "
        f"{n / per_iteration / 1e6:5.2f} M samples/s"
    )
    print("where it goes, thread time in nanoseconds a pixel an iteration:")
    for stage in STAGES:
        share = stage_sums[stage] / thread_total if thread_total else 0.0
        print(f"  {STAGE_NAMES[stage]:34s} {stage_sums[stage] / n * 1e9:7.1f} ns  {share:6.1%}")
    frame_setup = max(per_iteration * threads - thread_total, 0.0)
    print(f"  {'tile setup, threads, joins':34s} {frame_setup / n * 1e9:7.1f} ns")


def _print_against_embree(painted: list[float], alone: dict[str, list[float]], n: int, iterations: int, repeats: int):
    """Print each Embree query alone and the ratios of an iteration and of a whole painting to it, each the
    median of the repeats' pairs."""
    targets = {"embreex": "target <= 1.0x, goal 0.7x", "packets": "the limit: Embree's packets and nothing else"}
    for name, pairs in alone.items():
        embree = statistics.median(pairs)
        # each repeat pairs a painting with Embree alone right after it, under the same machine load: the
        # median of the pairwise ratios is steadier than the ratio of the medians
        ratios = sorted(p / a for p, a in zip(painted, pairs, strict=True))
        print(
            f"{name + ' alone, same rays and threads:':38s} {embree * 1e3:7.2f} ms   {n / embree / 1e6:5.2f} M rays/s"
        )
        print(
            f"  ratio iteration / {name}: {statistics.median(ratios):.2f}x median of {repeats} pairs "
            f"(spread {ratios[0]:.2f}-{ratios[-1]:.2f}; {targets[name]})"
        )
    whole = sorted(iterations * p / a for p, a in zip(painted, alone["embreex"], strict=True))
    print(
        f"a whole painting ({iterations} iterations) / one embreex pass: {statistics.median(whole):.2f}x "
        f"median of {repeats} pairs (spread {whole[0]:.2f}-{whole[-1]:.2f}; target <= 3.0x, goal 2.0x)"
    )
    packets = sorted(p / a for p, a in zip(painted, alone["packets"], strict=True))
    print(
        f"a whole painting / {iterations} passes of bare packets: {statistics.median(packets):.2f}x "
        f"median of {repeats} pairs (spread {packets[0]:.2f}-{packets[-1]:.2f}; target <= 1.0x, goal 0.6x)"
    )


def _screen_paths(trace, origins: np.ndarray, directions: np.ndarray, repeats: int) -> None:
    """The screen cells of the painting (``kernels.screencells``): what they cost to build and hold, which path
    answered the samples of an iteration, and what each path costs (one thread, over the whole image)."""
    screen, n = trace.screen, len(origins)
    if not screen.on:
        print(f"screen cells: none ({screencells.VARIABLE}={screencells.mode()}, or a moving eye or a panorama)")
        return
    print(
        f"screen cells: built in {screen.seconds * 1e3:.1f} ms; {screen.nbytes() / 1e3:.0f} kB "
        f"({screen.nbytes() / n:.2f} bytes a pixel; declared at most {screencells.BYTES}) and "
        f"{screen.records.nbytes / 1e6:.1f} MB of face records; "
        f"{(screen.cover == visibility.LONG_CELL).mean():.0%} of the cells long, "
        f"{(screen.cover >= 0).mean():.0%} covered by one face"
    )
    every = np.arange(n)
    counts = np.zeros(len(visibility.REASONS), np.int64)
    visibility.reasons(screen, origins, directions, every, counts)
    print(
        "samples by path: "
        + ", ".join(f"{name} {c / n:.1%}" for name, c in zip(visibility.REASONS, counts, strict=True))
    )
    face, queue = np.empty(n, np.int32), np.empty(n, np.int64)
    whole, part, alone = [], [], []
    for _ in range(repeats):
        clock = time.thread_time()
        answered = visibility.find_faces(
            screen=screen,
            embree=trace.embree,
            origins=origins,
            directions=directions,
            rays=every,
            face=face,
            queue=queue,
        )
        whole.append(time.thread_time() - clock)
        clock = time.thread_time()
        intersect_rays(trace.embree, origins, directions, queue[: n - answered], face, True)
        part.append(time.thread_time() - clock)
        clock = time.thread_time()
        intersect_rays(trace.embree, origins, directions, every, face, True)
        alone.append(time.thread_time() - clock)
    embree, lists = statistics.median(part), statistics.median(whole) - statistics.median(part)
    print(
        f"  the ray's face by path, thread time in ns a pixel an iteration: cells {lists / n * 1e9:.1f} "
        f"({answered / n:.1%} of the samples), Embree {embree / n * 1e9:.1f} "
        f"(the rest); Embree's packets for every sample {statistics.median(alone) / n * 1e9:.1f}"
    )


STAGE_NAMES = {
    "camera": "cameras (mapping, rays)",
    "intersect": "ray (screen cells or Embree, hit points)",
    "shade": "shading (and recording channels)",
    "bookkeeping": "carrying pixels (kept images, result)",
}


def _own_painting(
    scene: Scene, width: int, height: int, params: PaintParams, repeats: int, threads: int, alone: dict
) -> None:
    """The scene's own painting (its own mapping, samples and settings), against one embreex pass over the
    color mapping's rays measured above."""
    camera = scene.camera
    paint(scene, camera, width, height, params, threads=threads)  # compile what it needs
    seconds = []
    for _ in range(repeats):
        clock = time.perf_counter()
        paint(scene, camera, width, height, params, threads=threads)
        seconds.append(time.perf_counter() - clock)
    embreex = statistics.median(alone["embreex"])
    print(
        f"the scene's own painting ({params.iterations} iterations, {params.mapping} mapping, {params.spp} spp): "
        f"{statistics.median(seconds) * 1e3:.1f} ms, {statistics.median(seconds) / embreex:.2f}x one embreex pass"
    )
