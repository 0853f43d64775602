"""``rcp bench projection``: what a panorama and a stereo pair cost against the perspective painting of as many
pixels, and how often the two eyes of a pair disagree where they see the same surface.

Costs are medians of paintings timed in turn, one of each kind per round, so that the machine's drift falls on
both alike. Disagreement: each pixel of the left eye is followed to the point it sees and into the right eye;
where the right eye sees that very point (within 1% of its distance), the two eyes' paintings are compared, and
a pixel counts when their colours differ by more than :data:`RIVALRY` beyond what the plain renders differ there
(the smudges, not the view, disagree: in a headset the eyes then see two paintings).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import replace

import numpy as np

from ..camera import Camera, Region, eye_pixels, pixel_frames, project
from ..mappings import register_mapping, unregister_mapping
from ..painting import paint
from ..params import PaintParams
from ..scene import Scene
from ..scenefile import load_scene

RIVALRY = 16 / 255
PROBE = "bench-projection-probe"  # a mapping that moves nothing and reads what locates a hit


def _timed(scene: Scene, camera: Camera, width: int, height: int, params: PaintParams) -> float:
    start = time.perf_counter()
    paint(scene, camera, *camera.image_size(width, height), params)
    return time.perf_counter() - start


def costs(scene: Scene, width: int, repeats: int) -> dict[str, float]:
    """Median seconds of each kind of painting, fast on and off; an eye's image is ``width x width / 2``."""
    height = width // 2
    base = scene.camera.moved(projection="perspective", stereo="mono")
    kinds = {
        "perspective": base,
        "equirect": base.moved(projection="equirect"),
        "perspective stereo": base.moved(stereo="top-bottom"),
        "equirect stereo": base.moved(projection="equirect", stereo="top-bottom"),
    }
    times: dict[str, list[float]] = {}
    for fast in (True, False):
        params = replace(scene.paint, fast=fast)
        for camera in kinds.values():
            _timed(scene, camera, width, height, params)  # compiled, and the scene built, before timing
        for _ in range(repeats):
            for name, camera in kinds.items():
                times.setdefault(f"{name}, fast {'on' if fast else 'off'}", []).append(
                    _timed(scene, camera, width, height, params)
                )
    return {name: statistics.median(t) for name, t in times.items()}


def rivalry(scene: Scene, camera: Camera, width: int, height: int, params: PaintParams) -> tuple[float, int]:
    """The share of the left eye's pixels whose painting disagrees with the right eye's where both see the same
    surface point, and how many such pixels there are."""
    register_mapping(PROBE, {"depth", "direction"}, lambda data: np.zeros((len(data.color), 3)))
    try:
        full = camera.image_size(width, height)
        probe = PaintParams(eye_mapping=PROBE, lambda_e=1e-12, lambda_p=0.0, iterations=1, z_max=1e6)
        seen = paint(scene, camera, *full, probe).state
    finally:
        unregister_mapping(PROBE)
    plain = paint(scene, camera, *full, replace(params, iterations=1)).image.reshape(-1, 3)
    painted = paint(scene, camera, *full, params).image.reshape(-1, 3)
    region = Region(*full)
    i, j = region.pixel_coords()
    eyes, _, _, f = pixel_frames(camera, region, i, j)
    assert seen.direction is not None and seen.depth is not None, "the probe reads both"
    direction = seen.direction.astype(np.float64)
    along = seen.depth / np.einsum("ij,ij->i", direction, f)
    points = eyes + along[:, None] * direction
    hit = seen.depth < 1e5  # not the sky
    left = np.flatnonzero(hit & (_sides(camera, region, i, j) < 0))
    # into the right eye: from the camera's centre first, then from the eye of the pixel found (on the sphere
    # each column has its own), the nearest pixel
    target = np.empty(len(left), np.int64)
    right_eye = np.broadcast_to(np.asarray(camera.eye, np.float64), (len(left), 3))
    ok: np.ndarray = np.ones(len(left), bool)
    for _ in range(2):
        x, y, ok = project(camera, region, np.ones(len(left), np.int64), points[left] - right_eye)
        x = np.clip(np.rint(x), 0, region.full_width - 1).astype(np.int64)
        y = np.clip(np.rint(y), 0, region.full_height - 1).astype(np.int64)
        target = y * region.full_width + x
        right_eye = eyes[target]
    same = ok & hit[target] & (_sides(camera, region, i[target], j[target]) > 0)
    distance = np.linalg.norm(points[left] - right_eye, axis=1)
    same &= np.linalg.norm(points[target] - points[left], axis=1) < 0.01 * distance
    a, b = left[same], target[same]
    beyond = np.abs(painted[a] - painted[b]).max(axis=1) - np.abs(plain[a] - plain[b]).max(axis=1)
    return float((beyond > RIVALRY).mean()) if len(a) else 0.0, len(a)


def _sides(camera: Camera, region: Region, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    return eye_pixels(camera, region, i, j)[0]


def bench_projection(scene_name: str, width: int, repeats: int, ipd: float | None) -> None:
    scene = load_scene(scene_name)
    ipd = ipd if ipd is not None else scene.camera.ipd
    print(f"scene {scene_name}: {scene.paint.iterations} iterations, an eye's image {width}x{width // 2}, ipd {ipd:g}")
    scene.camera = scene.camera.moved(ipd=ipd)
    seconds = costs(scene, width, repeats)
    for fast in ("on", "off"):
        base = seconds[f"perspective, fast {fast}"]
        print(f"fast {fast}: perspective {base * 1e3:.0f} ms")
        for name in ("equirect", "perspective stereo", "equirect stereo"):
            t = seconds[f"{name}, fast {fast}"]
            mono = seconds[f"{name.split()[0]}, fast {fast}"]
            against = f"{t / mono:.2f}x its mono" if "stereo" in name else f"{t / base:.2f}x perspective"
            print(f"  {name:20s} {t * 1e3:7.0f} ms  {against} (targets: equirect 1.15x, stereo 2.1x)")
    for projection in ("perspective", "equirect"):
        camera = scene.camera.moved(projection=projection, stereo="side-by-side")
        share, pairs = rivalry(scene, camera, width, width // 2, scene.paint)
        print(f"eyes disagreeing, {projection} pair: {share:.1%} of the {pairs:,} pixels both eyes see")
