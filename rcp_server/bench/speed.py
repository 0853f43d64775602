"""``rcp bench speed``: where an iteration's time goes, and how close it comes to Embree alone.

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
from ..engine.kernels.embree import EmbreexScene
from ..painting.loop import STAGES, default_threads, paint, tile_rows
from ..painting.raytrace import Rays, assign_cameras, setup_tile
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
    scene = load_scene(scene_name)
    threads = threads or default_threads()
    # the exact path (fast off) against Embree: what tracing every ray costs beyond the tracing
    params = PaintParams(
        mapping="color", iterations=iterations, spp=1, lambda_p=float(scene.paint.lambda_p), fast=False
    )
    camera = scene.camera
    geometry, tracer = scene.geometry(0.0)
    print(
        f"scene {scene_name!r}: {geometry.face_count} triangles; {width}x{height}, 1 spp, "
        f"{iterations} iterations, color mapping, {threads} threads"
    )
    paint(scene, camera, width, height, params, threads=threads)  # compile kernels, build the BVH

    # the rays a painted iteration casts (those after the sixth), in the same row bands as the painting
    region = Region(width, height)
    state = paint(scene, camera, width, height, params, threads=threads).state
    setup = setup_tile(camera, region, params)
    n = region.pixel_count
    rays = Rays.allocate(n, 1)
    assign_cameras(state, setup, params, params.focus(camera), rays)
    origins, directions = rays.origins, rays.directions
    bands = [slice(t.y0 * width, (t.y0 + t.height) * width) for t in region.tiles(tile_rows(region, threads))]
    hit_fraction = float((tracer.intersect(origins, directions).face >= 0).mean()) if tracer else 0.0

    # the two references: embreex (one rtcIntersect1 a ray, from its loop) and Embree's own coherent packets
    # on the same rays, without anything around them (the limit of this machine)
    embreex = EmbreexScene(geometry.triangles) if tracer else None
    scratch = np.empty(n, np.int32)
    queries = {
        "embreex": embreex.bare_query if embreex else None,
        "packets": (lambda o, d: tracer.bare_query(o, d, scratch[: len(o)])) if tracer else None,
    }
    painted, stage_sums = [], dict.fromkeys(STAGES, 0.0)
    alone: dict[str, list[float]] = {name: [] for name in queries}
    with ThreadPoolExecutor(threads) as pool:
        for _ in range(repeats):
            clock = time.perf_counter()
            result = paint(scene, camera, width, height, params, threads=threads)
            painted.append((time.perf_counter() - clock) / iterations)
            for stage in STAGES:
                stage_sums[stage] += result.stage_seconds[stage] / iterations / repeats
            for name, query in queries.items():
                seconds = _embree_alone(query, origins, directions, bands, pool, iterations) if query else math.nan
                alone[name].append(seconds)

    per_iteration = statistics.median(painted)
    thread_total = sum(stage_sums.values())
    print(f"rays hitting geometry: {hit_fraction:.0%}")
    print(
        f"one iteration (wall, median of {repeats}): {per_iteration * 1e3:7.2f} ms   "
        f"{n / per_iteration / 1e6:5.2f} M samples/s"
    )
    for stage in STAGES:
        share = stage_sums[stage] / thread_total if thread_total else 0.0
        print(f"  {stage:12s} {stage_sums[stage] * 1e3:7.2f} ms thread time  {share:6.1%}")
    frame_setup = per_iteration * threads - thread_total
    print(f"  {'(tile setup, threads, joins)':12s} ~{max(frame_setup, 0.0) * 1e3:.2f} ms thread time")
    if tracer is None:
        print("Embree alone: nothing to compare with, this scene has no triangles (every ray sees the sky)")
        return
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
    _painting_against_one_iteration(scene, width, height, replace(scene.paint, iterations=iterations), repeats, threads)


def _painting_against_one_iteration(
    scene: Scene, width: int, height: int, params: PaintParams, repeats: int, threads: int
) -> None:
    """A whole painting with the scene's own settings, fast and exact, against one traced iteration: each
    repeat paints all three in turn, so each ratio pairs paintings made under the same machine load."""
    camera = scene.camera
    one = replace(params, iterations=1, fast=False)
    runs = {"one": one, "fast": params, "exact": replace(params, fast=False)}
    seconds: dict[str, list[float]] = {name: [] for name in runs}
    images = {}
    for settings in runs.values():  # compile what each needs
        paint(scene, camera, width, height, settings, threads=threads)
    for _ in range(repeats):
        for name, settings in runs.items():
            clock = time.perf_counter()
            images[name] = paint(scene, camera, width, height, settings, threads=threads).image
            seconds[name].append(time.perf_counter() - clock)
    print(
        f"\nthe scene's painting ({params.iterations} iterations, {params.mapping} mapping, {params.spp} spp), "
        f"against one traced iteration ({statistics.median(seconds['one']) * 1e3:.1f} ms):"
    )
    for name in ("fast", "exact"):
        ratios = sorted(p / o for p, o in zip(seconds[name], seconds["one"], strict=True))
        print(
            f"  {name:5s} {statistics.median(seconds[name]) * 1e3:7.1f} ms   {statistics.median(ratios):.2f}x "
            f"median of {repeats} pairs (spread {ratios[0]:.2f}-{ratios[-1]:.2f})"
            + ("; target <= 2.0x, goal 1.5x" if name == "fast" else "")
        )
    close = (np.abs(images["fast"] - images["exact"]).max(axis=2) <= 2 / 255 + 1e-6).mean()
    print(f"  fast against exact: {close:.2%} of pixels within 2/255 (target >= 99%)")
