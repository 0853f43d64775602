"""``rcp bench agreement``: how often the ``fast`` shortcuts change a pixel, against tracing every ray.

For each scene (the shipped ones, and any model file given) and each camera (the scene's own, two more
around its target, and one standing inside the model's bounds looking along its longest horizontal extent,
which for an interior is a view of the room), it paints every built-in mapping at 1 and 4 samples, with and
without noise, once with ``fast`` and once without, and prints the share of pixels whose color is within
2/255 of the exact painting's in every channel (the bound the tests hold: at least 99%).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from ..camera.camera import Camera
from ..painting.loop import paint
from ..scene.scene import Scene
from ..scene.scenefile import load_scene, scene_names
from ..settings.params import PaintParams

WITHIN = 2 / 255
TARGET = 0.99
MAPPINGS = ("color", "depth", "normal")


def cameras(scene: Scene) -> dict[str, Camera]:
    """The scene's camera, two turned about its target by +-35 degrees, and one inside the bounds."""
    base = scene.camera
    eye, target = np.asarray(base.eye, float), np.asarray(base.look_at, float)
    out = {"scene": base}
    for name, degrees in (("left", -35.0), ("right", 35.0)):
        a = math.radians(degrees)
        offset = eye - target
        turned = np.array(
            [
                offset[0] * math.cos(a) + offset[2] * math.sin(a),
                offset[1],
                -offset[0] * math.sin(a) + offset[2] * math.cos(a),
            ]
        )
        out[name] = replace(base, eye=tuple(target + turned))
    geometry, _ = scene.geometry(0.0)
    if geometry.face_count:
        points = geometry.triangles.reshape(-1, 3)
        lo, hi = points.min(axis=0), points.max(axis=0)
        center = (lo + hi) / 2
        inside = center + np.array([0.0, -0.2 * (hi[1] - lo[1]), 0.0])  # nearer the floor: eye height
        axis = 0 if hi[0] - lo[0] >= hi[2] - lo[2] else 2
        look = inside.copy()
        look[axis] += 0.5 * (hi[axis] - lo[axis])
        out["inside"] = Camera(tuple(inside), tuple(look), fov=60.0)
    return out


def settings(scene: Scene, mapping: str, spp: int, noise: float) -> PaintParams:
    """The scene's painting with ``mapping`` at a strength that smudges visibly (depth: by the model's size)."""
    geometry, _ = scene.geometry(0.0)
    size = float(np.ptp(geometry.triangles.reshape(-1, 3), axis=0).max()) if geometry.face_count else 10.0
    lambda_p = {"color": 12.0, "depth": 8.0 / max(size, 1e-6), "normal": 14.0}[mapping]
    return replace(
        scene.paint, mapping=mapping, lambda_p=lambda_p, lambda_e=0.0, spp=spp, noise=noise, method="raytrace"
    )


def agreement(refs: list[str], width: int, height: int) -> float:
    """Print one line a painting pair; returns the least share seen."""
    worst = 1.0
    for ref in refs:
        clock = time.perf_counter()
        scene = load_scene(ref)
        geometry, _ = scene.geometry(0.0)
        print(
            f"\n{ref}: {geometry.face_count} triangles, loaded in {time.perf_counter() - clock:.1f} s; {width}x{height}"
        )
        for camera_name, camera in cameras(scene).items():
            for mapping in MAPPINGS:
                for spp in (1, 4):
                    for noise in (0.0, 0.3):
                        params = settings(scene, mapping, spp, noise)
                        exact = paint(scene, camera, width, height, replace(params, fast=False)).image
                        fast = paint(scene, camera, width, height, params).image
                        share = float((np.abs(fast - exact).max(axis=2) <= WITHIN + 1e-6).mean())
                        worst = min(worst, share)
                        flag = "" if share >= TARGET else "   below the target"
                        print(f"  {camera_name:7s} {mapping:7s} {spp} spp noise {noise:.1f}: {share:7.2%}{flag}")
    print(f"\nleast share within 2/255: {worst:.2%} (target >= {TARGET:.0%})")
    return worst


def run(models: list[str], width: int, height: int) -> None:
    agreement(scene_names() + models, width, height)
