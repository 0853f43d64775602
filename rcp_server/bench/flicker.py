"""``rcp bench flicker [PATH]``: how much a painted film flickers, as video stylisation papers measure it.

The measure is the **warping error**: frame ``s`` (``t - 1``, short range; ``t - 7``, long range) warped into
frame ``t`` by the motion, and compared with it where both frames see the same thing::

    E(t, s) = sum_p M(p) |V_t(p) - V_s(w(p))|^2 / sum_p M(p),   E = the mean of E(t, s) over the film

with colors in [0, 1] and the squared difference summed over R, G and B. The ``E_warp`` of Lai et al. (2018,
"Learning Blind Video Temporal Consistency") as their released script computes it (``evaluate_WarpError.py``)
divides by the mask's entries over the three channels: the mean per channel, a third of this; the report gives
that too.

Here the motion is exact, not an optical flow: every pixel's centre ray of frame ``t`` is traced into the
scene, its point projected into frame ``s``'s camera (``camera.project``), and ``V_s`` read there
bilinearly. ``M`` masks what either camera cannot see: a point off frame ``s``'s screen, behind its camera, or
hidden there (the four pixels around it in frame ``s`` must see one surface, their distances spread by less
than a tenth, and the point within 2% of those distances; or the sky, all of them). A miss (the sky, at
infinity) warps by its direction. Scenes are taken to stand still (the geometry of frame ``t``).

A plain film (one iteration: the ray-traced image) has an error of its own: resampling edges and textures
between pixel grids. The painting's error is reported as a ratio to it: 1 is a painting that sticks to the
scene as well as the scene itself does; a pattern fixed to the screen (the shower door) is many times more.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..camera.camera import RAY_DTYPE, Camera, Region, directions_at, project
from ..media.camerapath import CameraPath, PathFrame, load_path
from ..painting.loop import paint
from ..painting.sequence import paint_sequence
from ..scene.scene import Scene
from ..settings.params import PaintParams

GAPS = (1, 7)
"""Frames back that a frame is compared with: the short and the long range."""
SAME_SURFACE = 0.02  # a point within 2% of the distances the pixels around it see is the point they see
CONTINUOUS = 0.1  # pixels whose distances spread over less than a tenth of it see one surface, not an edge
CHANNELS = 3  # the published E_warp (Lai et al. 2018's evaluate_WarpError.py) divides by the mask's R, G and B entries


@dataclass(frozen=True)
class Sight:
    """What a frame's pixel centres see: ``points`` (n, 3) float64 (eye + direction at a miss), ``hit`` (n,)
    bool, ``distance`` (n,) float64 from the eye (inf at a miss), ``direction`` (n, 3) unit."""

    points: np.ndarray
    hit: np.ndarray
    distance: np.ndarray
    direction: np.ndarray


def sight(scene: Scene, camera: Camera, width: int, height: int, time: float) -> Sight:
    """Trace the centre ray of every pixel (row-major) of a mono ``camera``'s ``width x height`` image."""
    region = Region(width, height)
    i, j = region.pixel_coords()
    d, *_ = directions_at(camera, region, i + 0.5, j + 0.5)
    direction = d / np.linalg.norm(d, axis=1, keepdims=True)
    eye = np.asarray(camera.eye, np.float64)
    _, tracer = scene.geometry(time)
    hit = np.zeros(len(i), bool)
    distance = np.full(len(i), np.inf)
    if tracer is not None:
        origins = np.broadcast_to(eye.astype(RAY_DTYPE), direction.shape).copy()
        hits = tracer.intersect(origins, direction.astype(RAY_DTYPE))
        hit = hits.face >= 0
        distance = np.where(hit, hits.t.astype(np.float64), np.inf)
    points = np.where(hit[:, None], eye + direction * np.where(hit, distance, 0.0)[:, None], eye + direction)
    return Sight(points, hit, distance, direction)


@dataclass(frozen=True)
class Warp:
    """Where each pixel of frame ``t`` lies in frame ``s``: continuous ``x, y`` (n,) (pixel centres on the
    integers) and ``mask`` (n,) bool, true where frame ``s`` sees the same point."""

    x: np.ndarray
    y: np.ndarray
    mask: np.ndarray


def warp(seen_t: Sight, camera_s: Camera, seen_s: Sight, width: int, height: int) -> Warp:
    """The warp from frame ``t`` (``seen_t``) to frame ``s``, with its occlusion and off-screen mask."""
    eye_s = np.asarray(camera_s.eye, np.float64)
    towards = np.where(seen_t.hit[:, None], seen_t.points - eye_s, seen_t.direction)
    x, y, ok = project(camera_s, Region(width, height), np.zeros(len(towards), np.int64), towards)
    edge = 1e-6  # a point on the screen's border, give or take rounding
    mask = ok & (x >= -edge) & (x <= width - 1 + edge) & (y >= -edge) & (y <= height - 1 + edge)
    x0 = np.clip(np.floor(x).astype(np.int64), 0, width - 1)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, height - 1)
    reach = np.linalg.norm(towards, axis=1)
    around = np.stack(
        [np.clip(y0 + dy, 0, height - 1) * width + np.clip(x0 + dx, 0, width - 1) for dx in (0, 1) for dy in (0, 1)]
    )
    near, far = seen_s.distance[around].min(axis=0), seen_s.distance[around].max(axis=0)
    sky = ~seen_s.hit[around].any(axis=0)
    with np.errstate(invalid="ignore"):  # inf - inf where the four see the sky
        surface = (
            seen_s.hit[around].all(axis=0)
            & (far - near <= CONTINUOUS * reach)  # no edge between the four
            & (reach >= near * (1 - SAME_SURFACE))
            & (reach <= far * (1 + SAME_SURFACE))
        )
    mask &= np.where(seen_t.hit, surface, sky)
    return Warp(x, y, mask)


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``image`` (h, w, 3) read at continuous ``x, y`` (n,) (centres on the integers, inside): (n, 3)."""
    h, w = image.shape[:2]
    x0 = np.clip(np.floor(x).astype(np.int64), 0, w - 2 if w > 1 else 0)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, h - 2 if h > 1 else 0)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


@dataclass(frozen=True)
class Flicker:
    """A film's warping error at each gap of :data:`GAPS` (mean over its frames) and the share of pixels
    compared."""

    error: dict[int, float]
    compared: dict[int, float]


class Warps:
    """The warps between the frames of one path at one size, traced once for every film measured on it."""

    def __init__(self, scene: Scene, shots: Sequence[PathFrame], width: int, height: int):
        seen = [sight(scene, shot.camera, width, height, shot.scene_time) for shot in shots]
        self.pairs = {
            gap: [
                (t, warp(seen[t], shots[t - gap].camera, seen[t - gap], width, height)) for t in range(gap, len(shots))
            ]
            for gap in GAPS
        }

    def measure(self, frames: Sequence[np.ndarray]) -> Flicker:
        """The warping error of ``frames`` (each (h, w, 3) float, in [0, 1]), one a shot."""
        error, compared = {}, {}
        for gap, pairs in self.pairs.items():
            errors, shares = [], []
            for t, w in pairs:
                now = frames[t].reshape(-1, 3)[w.mask].astype(np.float64)
                before = bilinear(np.asarray(frames[t - gap], np.float64), w.x[w.mask], w.y[w.mask])
                errors.append(float(np.mean(np.sum((now - before) ** 2, axis=1))) if len(now) else 0.0)
                shares.append(float(w.mask.mean()))
            error[gap] = float(np.mean(errors)) if errors else float("nan")
            compared[gap] = float(np.mean(shares)) if shares else 0.0
        return Flicker(error, compared)


def films(
    scene: Scene, shots: Sequence[PathFrame], width: int, height: int, params: PaintParams, temporal: int
) -> dict[str, Callable[[], list[np.ndarray]]]:
    """The films measured, by name, each painted when called: plain, painted per frame, painted temporally."""

    def paint_frame(camera, scene_time, frame_params, previous):
        return paint(scene, camera, width, height, frame_params, time=scene_time, previous=previous)

    def film(p: PaintParams, k: int | None) -> Callable[[], list[np.ndarray]]:
        return lambda: list(paint_sequence(paint_frame, shots, p, k))

    return {
        "plain": film(replace(params, iterations=1), None),
        "painted, per frame": film(params, None),
        f"painted, temporal {temporal}": film(params, temporal),
    }


def report(results: dict[str, Flicker]) -> list[str]:
    """The table, side by side, the errors per channel (the published scripts' normalisation), and the closing
    line of painted-to-plain ratios."""
    short, long = GAPS
    lines = [f"{'film':24s} {f'error t-{short}':>12s} {f'error t-{long}':>12s}   pixels compared"]
    for name, r in results.items():
        lines.append(
            f"{name:24s} {r.error[short]:12.6f} {r.error[long]:12.6f}   "
            f"{r.compared[short]:.0%} (t-{short}), {r.compared[long]:.0%} (t-{long})"
        )
    per_channel = [
        f"{name} {r.error[short] / CHANNELS:.6f} (t-{short}), {r.error[long] / CHANNELS:.6f} (t-{long})"
        for name, r in results.items()
    ]
    lines.append("per channel, as Lai et al. 2018's released E_warp script averages: " + "; ".join(per_channel))
    plain = results["plain"]
    ratios = [
        f"{name.removeprefix('painted, ')} {r.error[short] / plain.error[short]:.2f}x (t-{short}), "
        f"{r.error[long] / plain.error[long]:.2f}x (t-{long})"
        for name, r in results.items()
        if name != "plain"
    ]
    lines.append("painted-to-plain warping error: " + "; ".join(ratios))
    return lines


def flicker(args: argparse.Namespace) -> None:
    """``rcp bench flicker``: print each film's warping error and the painted-to-plain ratio."""
    from ..scene.scenefile import load_scene

    scene = load_scene(args.scene)
    params = scene.painting({} if args.boil is None else {"boil": args.boil})
    path: CameraPath = load_path(args.path, scene.camera, args.fps)
    shots = list(path.frames(0, args.frames))
    warps = Warps(scene, shots, args.width, args.height)
    print(
        f"rcp bench flicker: {Path(args.path).name} on {scene.name}, {len(shots)} frames of "
        f"{args.width}x{args.height} at {path.fps:g} fps (warping error: mean squared RGB difference in [0, 1])"
    )
    painted = films(scene, shots, args.width, args.height, params, args.temporal)
    results = {name: warps.measure(paint_film()) for name, paint_film in painted.items()}
    for line in report(results):
        print(line)
