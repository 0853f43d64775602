"""``rcp bench stability``: where each method breaks, measured on the shipped ``default`` scene and on
probe scenes built here.

* screen edges: the image method reads off screen through its edge mode; the ray tracer sees what is there;
* eye displacement (``lambda_e != 0``) and the disocclusions it opens: only ray tracing can paint it;
* extremes: large lambdas (rays leaving the scene, lookups leaving the screen), a grazing view, thin
  geometry, misses under the depth mapping, degenerate cameras, non-finite displacements;
* convergence: how much each iteration changes the image, over 1..20 iterations;
* a slow camera pan: flicker (frame-to-frame change beyond the plain render's own) and the shower-door
  test: do smudges move with the scene (as the paper claims) or stay on the screen?

Every painting compared here is at 1 sample per pixel, so the differences are the methods', not noise.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import binary_dilation

from ..camera.camera import Camera, CameraError, Region, directions_at
from ..camera.camera import project as camera_project
from ..painting.assign import Rays, assign_cameras, displacements, setup_tile
from ..painting.imagespace import bilinear, lookup_coords
from ..painting.loop import paint
from ..scene.meshes import Part, primitive
from ..scene.scene import Environment, Scene, SceneObject
from ..scene.scenefile import load_scene
from ..settings.mappings import register_mapping, unregister_mapping
from ..settings.params import EDGES, PaintParams
from .metrics import edge_band, psnr

# ---- measures ----


def mean_change(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute difference per channel, in [0, 1] units."""
    return float(np.abs(np.asarray(a, np.float64) - b).mean())


def pan(camera: Camera, degrees: float) -> Camera:
    """The camera turned about its up axis through the eye (a pan: the eye stays put)."""
    r, u, f = camera.basis()
    a = math.radians(degrees)
    turned = f * math.cos(a) - r * math.sin(a)  # positive degrees turn left
    return camera.moved(look_at=tuple(np.asarray(camera.eye) + turned))


def project(camera: Camera, width: int, height: int, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Continuous pixel coordinates (centres on the integers) where world ``directions`` (n, 3) from the eye
    land in ``camera``'s mono image (``camera.project``); NaN where they have no place (behind an image plane)."""
    x, y, ok = camera_project(camera, Region(width, height), np.zeros(len(directions), np.int64), directions)
    return np.where(ok, x, np.nan), np.where(ok, y, np.nan)


def primary_directions(camera: Camera, width: int, height: int) -> np.ndarray:
    """Unit directions of the rays through every pixel centre, (W*H, 3) float64, row-major."""
    region = Region(width, height)
    d, *_ = directions_at(camera, region, *(c + 0.5 for c in region.pixel_coords()))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    denominator = math.sqrt(float((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / denominator) if denominator > 0 else 0.0


def smudge_correlations(smudges: list[np.ndarray], cameras: list[Camera], lag: int) -> tuple[float, float]:
    """The shower-door test. ``smudges[k]`` (h, w, 3) is painting minus plain render of frame k, seen by
    ``cameras[k]`` (one eye, turning). For every pair (k, k + lag) it correlates frame k + lag's smudges
    with frame k's *carried with the scene* (each pixel looks up frame k where its own ray crossed frame k's
    image plane; a pan moves every depth alike) and *left on the screen* (the same pixel). Returns the two
    mean correlations (scene, screen), over the pixels whose ray was on screen in both frames."""
    h, w = smudges[0].shape[:2]
    scene, screen = [], []
    for k in range(len(smudges) - lag):
        later = cameras[k + lag]
        x, y = project(cameras[k], w, h, primary_directions(later, w, h))
        inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
        carried = bilinear(smudges[k], x[inside], y[inside], "clamp")
        now = smudges[k + lag].reshape(-1, 3)[inside]
        scene.append(_correlation(now, carried))
        screen.append(_correlation(now, smudges[k].reshape(-1, 3)[inside]))
    return float(np.mean(scene)), float(np.mean(screen))


def flicker(paintings: list[np.ndarray], plains: list[np.ndarray]) -> list[float]:
    """Per consecutive pair of frames: the painting's mean change minus the plain render's mean change."""
    return [
        mean_change(paintings[k + 1], paintings[k]) - mean_change(plains[k + 1], plains[k])
        for k in range(len(paintings) - 1)
    ]


# ---- probe scenes ----


def thin_poles_scene() -> Scene:
    """Upright poles 0.01 wide, 10 units ahead: about a tenth of a pixel at 320x180, in front of a sky."""
    poles = []
    for k, x in enumerate(np.linspace(-4.0, 4.0, 9)):
        part = primitive("box", extents=(0.01, 6.0, 0.01)).tinted((0.9, 0.1, 0.1))
        m = np.eye(4)
        m[:3, 3] = (x, -3.0, -10.0)
        poles.append(SceneObject(f"pole{k}", part, [(m, part)]))
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0))
    return Scene("thin", "thin poles", camera, Environment.constant((0.2, 0.4, 0.8)), None, poles, z_max=30.0)


def grazing_scene() -> Scene:
    """A vast checkered ground seen from 0.05 above it, looking along it: the view grazes the plane."""
    part = primitive("grid", size=(2000.0, 2000.0), divisions=(200, 200))
    checker = (np.floor(part.vertices[part.faces][:, :, 0].mean(axis=1) / 10) % 2)[:, None, None]
    colors = np.where(checker > 0, np.float32(0.9), np.float32(0.2)) * np.ones((1, 3, 3), np.float32)
    part = Part(part.vertices, part.faces, colors.astype(np.float32), part.corner_uv)
    ground = SceneObject("ground", part, [(np.eye(4), part)])
    camera = Camera((0.0, 0.05, 0.0), (0.0, 0.05, -1.0))
    return Scene("grazing", "grazing ground", camera, Environment.constant((0.5, 0.7, 0.9)), None, [ground])


BROKEN = "stability-broken"  # registered only while non_finite_section paints with it


def broken_field(data):
    """The color field with NaN in every other pixel and infinity in every fourth (a broken custom W)."""
    d = data.color_field().astype(np.float64)
    d[::2] = np.nan
    d[1::4] = np.inf
    return d


# ---- sections of the report ----


def edges_section(scene: Scene, width: int, height: int, params: PaintParams) -> tuple[dict, dict]:
    """Each edge mode of the image method against the ray-traced painting (same samples), in the edge band
    and inside it: after iteration 2 (the first lookup: bilinear against exact rays, plus the edge mode)
    and after the last (where small differences have fed back through the recursion). Also returns the
    final paintings, for the chart's crops."""
    band = edge_band(height, width)
    traced = paint(scene, scene.camera, width, height, params, keep_iterations=True).iterations
    images = {"raytrace": traced[-1]}
    out: dict[str, dict] = {}
    for edge in EDGES:
        p = replace(params, method="image", edge=edge)
        kept = paint(scene, scene.camera, width, height, p, keep_iterations=True).iterations
        images[edge] = kept[-1]
        out[edge] = {}
        for label, n in (("iteration2", 1), ("final", -1)):
            a, b = kept[n], traced[n]
            out[edge][label] = {
                "psnr_edge": psnr(a, b, band),
                "psnr_inner": psnr(a, b, ~band),
                "change_edge": mean_change(a[band], b[band]),
                "change_inner": mean_change(a[~band], b[~band]),
            }
    return out, images


def eye_section(scene: Scene, width: int, height: int, params: PaintParams, lambda_e: float) -> dict:
    """``lambda_e != 0``, ray traced, against the best the image method can do (``lambda_e = 0``): the error
    near depth discontinuities (where eye displacement opens disocclusions) and away from them."""
    probe = replace(params, lambda_e=lambda_e, eye_mapping="color")
    traced = paint(scene, scene.camera, width, height, probe).image
    image = paint(scene, scene.camera, width, height, replace(params, method="image")).image
    depth = paint(scene, scene.camera, width, height, PaintParams(mapping="depth", iterations=1)).state.depth
    assert depth is not None  # the depth mapping records it
    z = depth.reshape(height, width)
    jump = np.zeros_like(z, bool)
    jump[:, 1:] |= np.abs(np.diff(z, axis=1)) > 0.1 * np.minimum(z[:, 1:], z[:, :-1])
    jump[1:, :] |= np.abs(np.diff(z, axis=0)) > 0.1 * np.minimum(z[1:, :], z[:-1, :])
    near = binary_dilation(jump, iterations=max(2, round(params.lambda_p)))
    return {
        "lambda_e": lambda_e,
        "psnr": psnr(image, traced),
        "near_silhouettes_fraction": float(near.mean()),
        "change_near_silhouettes": mean_change(image[near], traced[near]),
        "change_elsewhere": mean_change(image[~near], traced[~near]),
    }


def _miss_fraction(scene: Scene, camera: Camera, state, params: PaintParams, width: int, height: int) -> float:
    """The fraction of the rays the next iteration would cast from ``state`` that leave the scene."""
    _, tracer = scene.geometry(0.0)
    region = Region(width, height)
    rays = Rays.allocate(region.pixel_count, 1)
    assign_cameras(state, setup_tile(camera, region, params), params, params.focus(camera), rays)
    return 1.0 if tracer is None else float((tracer.intersect(rays.origins, rays.directions).face < 0).mean())


def _off_screen_fraction(camera: Camera, state, params: PaintParams, width: int, height: int) -> float:
    """The fraction of the lookups the next image iteration would make from ``state`` that leave the screen."""
    region = Region(width, height)
    v_p, _ = displacements(state, setup_tile(camera, region, params), params, params.focus(camera))
    x, y, _ = lookup_coords(v_p, camera, region)
    return float(((x < 0) | (x > width - 1) | (y < 0) | (y > height - 1)).mean())


def _both(scene: Scene, camera: Camera, width: int, height: int, params: PaintParams) -> dict:
    plain = paint(scene, camera, width, height, replace(params, iterations=1)).image
    out = {}
    for method in ("raytrace", "image"):
        result = paint(scene, camera, width, height, replace(params, method=method))
        image = result.image
        out[method] = {
            "finite": bool(np.all(np.isfinite(image))),
            "in_range": bool(np.all((image >= 0) & (image <= 1))),
            "change_from_plain": mean_change(image, plain),
        }
        if method == "raytrace":
            traced, state = image, result.state
    out["image"]["psnr_against_raytrace"] = psnr(image, traced)
    out["raytrace"]["rays_leaving_scene"] = _miss_fraction(scene, camera, state, params, width, height)
    out["image"]["lookups_off_screen"] = _off_screen_fraction(camera, result.state, params, width, height)
    return out


def extremes_section(scene: Scene, width: int, height: int, params: PaintParams, lambdas) -> dict:
    out: dict = {"lambda_p": {}}
    for lam in lambdas:
        out["lambda_p"][str(lam)] = _both(scene, scene.camera, width, height, replace(params, lambda_p=float(lam)))
    grazing = grazing_scene()
    out["grazing"] = _both(grazing, grazing.camera, width, height, replace(params, mapping="color"))
    thin = thin_poles_scene()
    sky_color = thin.environment.image.reshape(3)
    thin_out = {}

    def touched(image):  # pixels that show any pole at all: more than 0.05 away from the sky
        return float((np.abs(image - sky_color).max(axis=2) > 0.05).mean())

    for spp in (1, 16):
        p = replace(params, spp=spp)
        plain = paint(thin, thin.camera, width, height, replace(p, iterations=1)).image
        entry = {"plain_pole_fraction": touched(plain)}
        for method in ("raytrace", "image"):
            image = paint(thin, thin.camera, width, height, replace(p, method=method)).image
            entry[f"{method}_pole_fraction"] = touched(image)
        thin_out[f"spp{spp}"] = entry
    out["thin_geometry"] = thin_out
    sky = Scene("sky", "sky", Camera((0, 0, 0), (0, 0, -1)), Environment.constant((0.9, 0.2, 0.4)), z_max=42.0)
    misses = {}
    for method in ("raytrace", "image"):
        depth = paint(sky, sky.camera, 64, 36, PaintParams(mapping="depth", method=method, lambda_p=9.0)).state.depth
        misses[method] = {"depth_is_z_max": bool(np.all(depth == np.float32(42.0)))}
    out["misses_depth_mapping"] = misses
    degenerate = {}
    for name, args in {
        "eye_on_target": ((1, 2, 3), (1, 2, 3)),
        "up_parallel_to_view": ((0, 0, 0), (0, 5, 0)),
        "nan_eye": ((math.nan, 0, 0), (0, 0, -1)),
        "infinite_target": ((0, 0, 0), (0, 0, -math.inf)),
    }.items():
        try:
            Camera(*args)
            degenerate[name] = "accepted"
        except CameraError as exc:
            degenerate[name] = f"CameraError: {exc}"
    out["degenerate_cameras"] = degenerate
    out["non_finite_displacements"] = non_finite_section(scene, width, height, params)
    return out


def non_finite_section(scene: Scene, width: int, height: int, params: PaintParams) -> dict:
    """Both methods with a mapping whose field is NaN or infinite in three pixels out of four: is every pixel
    finite, and do those pixels keep the plain render (a non-finite displacement moves nothing)?"""
    plain = paint(scene, scene.camera, width, height, replace(params, iterations=1)).image.reshape(-1, 3)
    out = {}
    register_mapping(BROKEN, reads={"color"}, field=broken_field)
    try:
        for method in ("raytrace", "image"):
            p = replace(params, mapping=BROKEN, method=method)
            image = paint(scene, scene.camera, width, height, p).image.reshape(-1, 3)
            out[method] = {
                "finite": bool(np.all(np.isfinite(image))),
                "non_finite_pixels_kept_plain": bool(
                    np.array_equal(image[::2], plain[::2]) and np.array_equal(image[1::4], plain[1::4])
                ),
            }
    finally:
        unregister_mapping(BROKEN)
    return out


def convergence_section(scene: Scene, width: int, height: int, params: PaintParams, iterations: int) -> dict:
    """Mean change from each iteration to the next, 1..iterations, for both methods."""
    out = {}
    for method in ("raytrace", "image"):
        p = replace(params, method=method, iterations=iterations)
        kept = paint(scene, scene.camera, width, height, p, keep_iterations=True).iterations
        out[method] = [mean_change(kept[n + 1], kept[n]) for n in range(iterations - 1)]
    return out


def temporal_section(scene: Scene, width: int, height: int, params: PaintParams, frames: int, degrees: float) -> dict:
    """A slow pan, ``degrees`` per frame: per-frame and temporal (k = 1) painting with both methods."""
    cameras = [pan(scene.camera, degrees * k) for k in range(frames)]
    plains = [paint(scene, c, width, height, replace(params, iterations=1)).image for c in cameras]
    lag = max(1, frames - 1)
    runs, painted = {}, {}
    for method in ("raytrace", "image"):
        for mode in ("per-frame", "temporal"):
            p = replace(params, method=method)
            images, state = [], None
            for k, c in enumerate(cameras):
                q = replace(p, iterations=1) if mode == "temporal" and k > 0 else p
                result = paint(scene, c, width, height, q, previous=state if mode == "temporal" else None)
                state = result.state
                images.append(result.image)
            painted[method, mode] = images
            smudges = [a - b for a, b in zip(images, plains, strict=True)]
            scene_corr, screen_corr = smudge_correlations(smudges, cameras, lag)
            runs[f"{method} {mode}"] = {
                "flicker": flicker(images, plains),
                "smudge_with_scene": scene_corr,
                "smudge_with_screen": screen_corr,
            }
    # temporal drift: how far each temporal frame is from the painting of its own camera (what per-frame
    # shows, and Save gives), against the plain render's distance from it
    per_frame = painted["raytrace", "per-frame"]
    drift = [psnr(t, f) for t, f in zip(painted["raytrace", "temporal"], per_frame, strict=True)]
    plain_drift = [psnr(p, f) for p, f in zip(plains, per_frame, strict=True)]
    # the control: a smudge pattern fixed on the screen, as a filter over the plain render would make
    rng = np.random.default_rng(0)
    fixed = rng.normal(0.0, 0.05, (height, width, 3))
    scene_corr, screen_corr = smudge_correlations([fixed] * frames, cameras, lag)
    runs["screen-fixed pattern"] = {"flicker": [], "smudge_with_scene": scene_corr, "smudge_with_screen": screen_corr}
    pixels_per_frame = degrees / (2 * math.degrees(math.atan(scene.camera.half_height()))) * height
    return {
        "frames": frames,
        "degrees_per_frame": degrees,
        "pixels_per_frame": pixels_per_frame,
        "lag": lag,
        "plain_change": [mean_change(plains[k + 1], plains[k]) for k in range(frames - 1)],
        "runs": runs,
        "temporal_psnr_to_per_frame": drift,
        "plain_psnr_to_per_frame": plain_drift,
    }


def walk(camera: Camera, distance: float) -> Camera:
    """The camera walked ``distance`` scene units along its view (eye and look-at together)."""
    step = camera.basis()[2] * distance
    return camera.moved(eye=tuple(np.add(camera.eye, step)), look_at=tuple(np.add(camera.look_at, step)))


def _world_points(scene: Scene, camera: Camera, width: int, height: int) -> np.ndarray:
    """What the pixel centres see, (W*H, 3) float64 world points (NaN: the sky)."""
    register_mapping("bench-points", {"position"}, lambda data: np.zeros((len(data.color), 3)))
    try:
        probe = PaintParams(iterations=1, lambda_p=0.0, lambda_e=1.0, eye_mapping="bench-points")
        state = paint(scene, camera, width, height, probe).state
    finally:
        unregister_mapping("bench-points")
    assert state.position is not None  # the probe reads it
    return state.position.astype(np.float64)


def carried_flicker(
    paintings: list[np.ndarray], plains: list[np.ndarray], cameras: list[Camera], scene: Scene
) -> list[float]:
    """Flicker beyond the scene's own motion, per consecutive pair of frames: frame k + 1 against frame k
    carried with the scene (each pixel looks up frame k where the world point it sees projects in frame k's
    camera), the painting's mean difference minus the plain render's, over what both frames see of the
    scene (not the sky). A pattern that stays on its surfaces scores 0 however fine; one that stays on the
    screen scores what the scene moves under it."""
    h, w = paintings[0].shape[:2]
    out = []
    for k in range(len(paintings) - 1):
        points = _world_points(scene, cameras[k + 1], w, h)
        x, y = project(cameras[k], w, h, points - np.asarray(cameras[k].eye))  # the sky (NaN) is left out
        inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)

        residuals = []
        for images in (paintings, plains):
            carried = bilinear(images[k], x[inside], y[inside], "clamp")
            residuals.append(float(np.abs(images[k + 1].reshape(-1, 3)[inside] - carried).mean()))
        out.append(residuals[0] - residuals[1])
    return out


def noise_section(scene: Scene, width: int, height: int, frames: int, step: float, degrees: float) -> dict:
    """The noisy styles (``styles.py``) on the paper's two kinds of randomness: each style as it is (surface
    noise, a function of the world point) and with screen noise of the same strength instead (a fixed vector
    per pixel, what the styles were before). Per-frame paintings of a walk (``step`` scene units a frame) and
    of a pan (``degrees`` a frame): flicker carried with the scene (:func:`carried_flicker`) and frame to frame
    (:func:`flicker`, which counts a fine pattern moving with its surfaces as change)."""
    moves = {
        "walk": [walk(scene.camera, step * k) for k in range(frames)],
        "pan": [pan(scene.camera, degrees * k) for k in range(frames)],
    }
    plain = replace(scene.paint, iterations=1, spp=1)
    plains = {how: [paint(scene, c, width, height, plain).image for c in cameras] for how, cameras in moves.items()}
    out = {}
    for name in ("fractured", "cross-hatching"):
        surface = scene.painting({"style": name})
        screen = replace(surface, noise=max(surface.surface_noise, surface.surface_scale), surface_noise=0.0)
        screen = replace(screen, surface_scale=0.0, hatch=False)
        for kind, params in (("surface", surface), ("screen", screen)):
            run: dict[str, Any] = {}
            for how, cameras in moves.items():
                images = [paint(scene, c, width, height, params).image for c in cameras]
                run[f"{how}_flicker"] = carried_flicker(images, plains[how], cameras, scene)
                run[f"{how}_change"] = flicker(images, plains[how])
            out[f"{name} {kind}"] = run
    return {"frames": frames, "step": step, "degrees": degrees, "runs": out}


# ---- the report ----


def chart(report: dict, crops: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(16, 9))
    _corners(axes[0, 0], report, crops)
    _edge_band(axes[0, 1], report, crops)
    _convergence(axes[0, 2], report, crops)
    _flicker(axes[1, 0], report, crops)
    _shower_door(axes[1, 1], report, crops)
    _large_lambdas(axes[1, 2], report, crops)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _corners(ax, report: dict, crops: dict) -> None:
    """Panel (a): the bottom-right corner of each painting, where lookups leave the screen."""
    h, w = crops["raytrace"].shape[:2]
    ch, cw = h // 3, w // 4
    tiles = [crops[name][h - ch :, w - cw :] for name in ("raytrace", *EDGES)]
    ax.imshow(np.clip(np.concatenate([np.concatenate(tiles[:2], 1), np.concatenate(tiles[2:], 1)], 0), 0, 1))
    ax.set_title("bottom-right corner: raytrace | clamp\nwrap | mirror", fontsize=10)
    ax.axis("off")


def _edge_band(ax, report: dict, crops: dict) -> None:
    """Panel (b): edge band against inside, per edge mode."""
    edges = report["edges"]
    x = np.arange(len(EDGES))
    for k, (label, name) in enumerate((("iteration2", "iteration 2"), ("final", "last iteration"))):
        ax.bar(x + 0.2 * k - 0.3, [edges[e][label]["change_edge"] for e in EDGES], 0.2, label=f"{name}, edge band")
        ax.bar(x + 0.2 * k + 0.1, [edges[e][label]["change_inner"] for e in EDGES], 0.2, label=f"{name}, inside")
    ax.set_xticks(x, [f"image, {e}" for e in EDGES])
    ax.set_ylabel("mean |image - raytrace| per channel")
    ax.set_title("image method against ray tracing (same samples)", fontsize=10)
    ax.legend(fontsize=8)


def _convergence(ax, report: dict, crops: dict) -> None:
    """Panel (c): convergence."""
    for method, changes in report["convergence"].items():
        ax.plot(range(2, len(changes) + 2), changes, marker="o", ms=3, label=method)
    ax.set_yscale("log")
    ax.set_xlabel("iteration n")
    ax.set_ylabel("mean |I_n - I_(n-1)|")
    ax.set_title("convergence", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")


def _flicker(ax, report: dict, crops: dict) -> None:
    """Panel (d): flicker over the pan."""
    temporal = report["temporal"]
    ax.plot(temporal["plain_change"], color="black", lw=1, ls=":", label="plain render's own change")
    for name, run in temporal["runs"].items():
        if run["flicker"]:
            ax.plot(run["flicker"], marker=".", label=name)
    ax.axhline(0, color="grey", lw=0.8)
    ax.set_xlabel("frame pair (k, k + 1)")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.set_ylabel("painting's change - plain's change")
    ax.set_title(f"flicker, pan {temporal['pixels_per_frame']:.1f} px/frame", fontsize=10)
    ax.legend(fontsize=7)


def _shower_door(ax, report: dict, crops: dict) -> None:
    """Panel (e): the shower door."""
    temporal = report["temporal"]
    names = list(temporal["runs"])
    x = np.arange(len(names))
    ax.bar(x - 0.2, [temporal["runs"][n]["smudge_with_scene"] for n in names], 0.4, label="carried with the scene")
    ax.bar(x + 0.2, [temporal["runs"][n]["smudge_with_screen"] for n in names], 0.4, label="left on the screen")
    ax.set_xticks(x, [n.replace(" ", "\n") for n in names], fontsize=7)
    ax.set_ylabel(f"correlation of smudges, frames {temporal['lag']} apart")
    ax.set_title("shower door: do smudges stick to the scene?", fontsize=10)
    ax.legend(fontsize=8)


def _large_lambdas(ax, report: dict, crops: dict) -> None:
    """Panel (f): large lambdas."""
    lambdas = report["extremes"]["lambda_p"]
    keys = list(lambdas)
    values = [float(k) for k in keys]
    ax.plot(
        values,
        [lambdas[k]["raytrace"]["rays_leaving_scene"] for k in keys],
        marker="o",
        label="raytrace: rays leaving the scene (sky)",
    )
    ax.plot(
        values, [lambdas[k]["image"]["lookups_off_screen"] for k in keys], marker="s", label="image: lookups off screen"
    )
    ax.plot(
        values,
        [lambdas[k]["raytrace"]["change_from_plain"] for k in keys],
        ls="--",
        label="raytrace: change from plain",
    )
    ax.plot(values, [lambdas[k]["image"]["change_from_plain"] for k in keys], ls="--", label="image: change from plain")
    ax.set_xscale("log")
    ax.set_xlabel("lambda_p (pixels)")
    ax.set_ylabel("fraction")
    ax.set_title("large lambdas", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")


def run(out: Path, quick: bool = False, noise_only: bool = False) -> dict:
    """Measure, write ``out/stability.json`` and ``out/stability.png``, print a summary; returns the report.
    ``noise_only``: the walk flicker of the two kinds of noise alone (:func:`noise_section`), printed."""
    width, height = (320, 180) if quick else (640, 360)
    frames = 8 if quick else 16
    started = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    scene = load_scene("default")
    noise = noise_section(scene, width, height, frames, 0.5, 0.25)
    if noise_only:
        noise_summary(noise, width, height)
        return {"noise": noise}
    base = replace(scene.paint, lambda_e=0.0, spp=1)
    base = replace(base, lambda_p=base.lambda_p * height / 360)  # the same painting at any resolution
    edges, crops = edges_section(scene, width, height, base)
    report: dict[str, Any] = {
        "scene": "default",
        "size": [width, height],
        "params": base.settings(),
        "edges": edges,
        "eye_displacement": eye_section(scene, width, height, base, 0.08),
        "extremes": extremes_section(scene, width, height, base, (1, 4, 16, 64, 256, 1024)),
        "convergence": convergence_section(scene, width, height, base, 20),
        "temporal": temporal_section(scene, width, height, base, frames, 0.25),
        "noise": noise,
    }
    report["seconds"] = time.perf_counter() - started
    (out / "stability.json").write_text(json.dumps(report, indent=1))
    chart(report, crops, out / "stability.png")
    summary(report)
    print(f"wrote {out / 'stability.json'} and {out / 'stability.png'} in {report['seconds']:.0f} s")
    return report


def noise_summary(noise: dict, width: int, height: int) -> None:
    print(
        f"noisy styles, per-frame paintings at {width}x{height} over {noise['frames']} frames, a walk of "
        f"{noise['step']} units/frame and a pan of {noise['degrees']} degrees/frame: mean flicker carried with "
        "the scene (beyond the plain render's) / frame-to-frame change (beyond the plain render's):"
    )
    for name, run in noise["runs"].items():
        walk_, pan_ = (
            f"{np.mean(run[f'{how}_flicker']):+.4f} / {np.mean(run[f'{how}_change']):+.4f}" for how in ("walk", "pan")
        )
        print(f"  {name:24s} walk {walk_}   pan {pan_}")


def summary(report: dict) -> None:
    print(f"scene {report['scene']!r}, {report['size'][0]}x{report['size'][1]}, 1 spp")
    print("screen edges, image method against ray tracing (mean |difference| per channel):")
    for edge, e in report["edges"].items():
        first, last = e["iteration2"], e["final"]
        print(
            f"  {edge:7s} iteration 2: edge band {first['change_edge']:.4f} inside {first['change_inner']:.4f};"
            f"  last: edge band {last['change_edge']:.4f} inside {last['change_inner']:.4f}"
        )
    eye = report["eye_displacement"]
    print(
        f"lambda_e {eye['lambda_e']}: image (lambda_e 0) against ray tracing: {eye['psnr']:.1f} dB; "
        f"near silhouettes {eye['change_near_silhouettes']:.4f}, elsewhere {eye['change_elsewhere']:.4f}"
    )
    print("large lambda_p: rays leaving the scene (raytrace) / lookups off screen (image) / all finite:")
    for lam, e in report["extremes"]["lambda_p"].items():
        finite = e["raytrace"]["finite"] and e["image"]["finite"]
        print(
            f"  {lam:>5s} px: {e['raytrace']['rays_leaving_scene']:.2f} / {e['image']['lookups_off_screen']:.2f}"
            f"  image vs raytrace {e['image']['psnr_against_raytrace']:.1f} dB  finite {finite}"
        )
    g = report["extremes"]["grazing"]
    print(
        f"grazing view: image vs raytrace {g['image']['psnr_against_raytrace']:.1f} dB, finite "
        f"{g['raytrace']['finite'] and g['image']['finite']}"
    )
    for spp, e in report["extremes"]["thin_geometry"].items():
        if spp.startswith("spp"):
            print(
                f"thin poles at {spp}: pixels showing a pole: plain {e['plain_pole_fraction']:.4f}, "
                f"raytrace {e['raytrace_pole_fraction']:.4f}, image {e['image_pole_fraction']:.4f}"
            )
    print(f"misses under the depth mapping record z_max: {report['extremes']['misses_depth_mapping']}")
    for name, result in report["extremes"]["degenerate_cameras"].items():
        print(f"degenerate camera {name}: {result}")
    print(f"non-finite displacements: {report['extremes']['non_finite_displacements']}")
    conv = report["convergence"]
    print(
        "convergence, mean change at iterations 2, 6, 20: "
        + "; ".join(f"{m} {c[0]:.4f} {c[4]:.4f} {c[-1]:.4f}" for m, c in conv.items())
    )
    t = report["temporal"]
    print(
        f"pan of {t['pixels_per_frame']:.2f} px/frame over {t['frames']} frames; smudge correlation "
        f"{t['lag']} frames apart, carried with the scene / left on the screen; mean flicker:"
    )
    for name, r in t["runs"].items():
        mean_flicker = f"{np.mean(r['flicker']):+.4f}" if r["flicker"] else "   -   "
        print(f"  {name:22s} {r['smudge_with_scene']:.3f} / {r['smudge_with_screen']:.3f}   flicker {mean_flicker}")
    drift = ", ".join(f"{v:.1f}" for v in t["temporal_psnr_to_per_frame"])
    print(f"temporal drift: PSNR (dB) of each ray-traced temporal frame to its camera's painting: {drift}")
    plain = ", ".join(f"{v:.1f}" for v in t["plain_psnr_to_per_frame"])
    print(f"  (the plain render's, for scale: {plain})")
    noise_summary(report["noise"], *report["size"])
