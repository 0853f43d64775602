"""``rcp bench projection``: what a panorama and a stereo pair cost against the perspective painting of as many
pixels, and how often the two eyes of a pair disagree where they see the same surface.

Costs are medians of paintings timed in turn, one of each kind per round, so that the machine's drift falls on
both alike. Disagreement: where the two eyes see the same surface point (``stereo.partners``), their paintings
are compared, and
a pixel counts when their colours differ by more than :data:`RIVALRY` beyond what the plain renders differ there
(the smudges, not the view, disagree: in a headset the eyes then see two paintings).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import replace

import numpy as np

from ..camera.camera import Camera, Region, eye_pixels
from ..engine import kernels
from ..painting.loop import paint
from ..painting.seen import visible_faces
from ..painting.stereo import partners
from ..scene.scene import Scene
from ..scene.scenefile import load_scene
from ..settings.params import PaintParams

RIVALRY = 16 / 255


def _timed(scene: Scene, camera: Camera, width: int, height: int, params: PaintParams) -> float:
    start = time.perf_counter()
    paint(scene, camera, *camera.image_size(width, height), params)
    return time.perf_counter() - start


def costs(scene: Scene, width: int, repeats: int) -> dict[str, float]:
    """Median seconds of each kind of painting; an eye's image is ``width x width / 2``."""
    height = width // 2
    base = scene.camera.moved(projection="perspective", stereo="mono")
    kinds = {
        "perspective": base,
        "equirect": base.moved(projection="equirect"),
        "perspective stereo": base.moved(stereo="top-bottom"),
        "equirect stereo": base.moved(projection="equirect", stereo="top-bottom"),
    }
    times: dict[str, list[float]] = {}
    for camera in kinds.values():
        _timed(scene, camera, width, height, scene.paint)  # compiled, and the scene built, before timing
    for _ in range(repeats):
        for name, camera in kinds.items():
            times.setdefault(name, []).append(_timed(scene, camera, width, height, scene.paint))
    return {name: statistics.median(t) for name, t in times.items()}


def rivalry(scene: Scene, camera: Camera, width: int, height: int, params: PaintParams) -> tuple[float, int]:
    """The share of the left eye's pixels whose painting disagrees with the right eye's where both see the same
    surface point (``stereo.partners``), and how many such pixels there are."""
    full = camera.image_size(width, height)
    region = Region(*full)
    seen = kernels.Seen.empty(*full)
    visible_faces(scene, 0.0, camera, region, seen)
    pair = partners(camera, region, seen)
    side, _, _ = eye_pixels(camera, region, *region.pixel_coords())
    left = np.flatnonzero((side < 0) & (pair >= 0) & (seen.face >= 0))
    plain = paint(scene, camera, *full, replace(params, iterations=1)).image.reshape(-1, 3)
    painted = paint(scene, camera, *full, params).image.reshape(-1, 3)
    a, b = left, pair[left]
    beyond = np.abs(painted[a] - painted[b]).max(axis=1) - np.abs(plain[a] - plain[b]).max(axis=1)
    return float((beyond > RIVALRY).mean()) if len(a) else 0.0, len(a)


def bench_projection(scene_name: str, width: int, repeats: int, ipd: float | None) -> None:
    scene = load_scene(scene_name)
    ipd = ipd if ipd is not None else scene.camera.ipd
    print(f"scene {scene_name}: {scene.paint.iterations} iterations, an eye's image {width}x{width // 2}, ipd {ipd:g}")
    scene.camera = scene.camera.moved(ipd=ipd)
    seconds = costs(scene, width, repeats)
    base = seconds["perspective"]
    print(f"perspective {base * 1e3:.0f} ms")
    for name in ("equirect", "perspective stereo", "equirect stereo"):
        t = seconds[name]
        mono = seconds[name.split()[0]]
        against = f"{t / mono:.2f}x its mono" if "stereo" in name else f"{t / base:.2f}x perspective"
        print(f"  {name:20s} {t * 1e3:7.0f} ms  {against} (targets: equirect 1.15x, stereo 2.1x)")
    for projection in ("perspective", "equirect"):
        camera = scene.camera.moved(projection=projection, stereo="side-by-side")
        for eyes in ("own", "shared"):
            share, pairs = rivalry(scene, camera.moved(eyes=eyes), width, width // 2, scene.paint)
            print(f"eyes disagreeing, {projection} pair, eyes {eyes}: {share:.1%} of the {pairs:,} pixels both see")
