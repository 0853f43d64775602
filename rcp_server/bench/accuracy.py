"""``rcp bench accuracy``: time per frame against error, for each way to paint, over samples per pixel and resolution.

The curves (:data:`CURVES`): the ray-traced method (``raytrace``, the default) and the image-space method
(``image``).

Every point paints a shipped scene with its own painting settings (``lambda_e`` set to 0, so every curve
paint the same thing), at ``spp`` samples per pixel and at a fraction ``scale`` of the resolution
(``lambda_p``, which counts pixels, scaled with it so that the painting is the same), upscaled bilinearly
to full size. Its error is measured against the *converged reference*: the ray-traced painting at full
resolution with many samples per pixel, every ray traced. It is the ground truth for all, so the image method's
error includes its bias (off-screen lookups, bilinear mixing across silhouettes), which no number of
samples removes. How converged the reference itself is: the same painting with half its samples,
measured against it (``reference_floor``).
"""

from __future__ import annotations

import json
import statistics
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..painting.loop import default_threads, paint
from ..scene.scenefile import load_scene
from .metrics import edge_band, psnr, ssim, upscale

SCENES = ("default", "sea", "sky")
CURVES: dict[str, dict[str, Any]] = {  # name -> the settings that paint it
    "raytrace": {"method": "raytrace"},
    "image": {"method": "image"},
}


@dataclass(frozen=True)
class Sweep:
    width: int
    height: int
    spps: tuple[int, ...]
    scales: tuple[float, ...]
    reference_spp: int
    repeats: int  # timed paintings per point (the median counts)


QUICK = Sweep(320, 180, (1, 2, 4, 8), (1.0, 0.5, 0.25), 64, 3)
FULL = Sweep(640, 360, (1, 2, 4, 8, 16), (1.0, 0.5, 0.25), 64, 3)


def measure(scene_name: str, sweep: Sweep, threads: int) -> tuple[list[dict], dict]:
    """Every (method, spp, scale) point of one scene, and what its reference is."""
    scene = load_scene(scene_name)
    camera = scene.camera
    base = replace(scene.paint, lambda_e=0.0, method="raytrace", spp=1)
    w, h = sweep.width, sweep.height
    clock = time.perf_counter()
    reference = paint(scene, camera, w, h, replace(base, spp=sweep.reference_spp), threads=threads).image
    reference_ms = (time.perf_counter() - clock) * 1e3
    half = paint(scene, camera, w, h, replace(base, spp=sweep.reference_spp // 2), threads=threads).image
    band = edge_band(h, w)
    floor = {"psnr": psnr(half, reference), "ssim": ssim(half, reference), "psnr_edge": psnr(half, reference, band)}
    points = []
    for method, settings in CURVES.items():
        for spp in sweep.spps:
            for scale in sweep.scales:
                sw, sh = max(1, round(w * scale)), max(1, round(h * scale))
                # lambda_p counts pixels: at a fraction of the resolution the same smudge is fewer pixels
                params = replace(base, **settings, spp=spp, lambda_p=base.lambda_p * sh / h)
                paint(scene, camera, sw, sh, params, threads=threads)  # warm: compiled kernels, caches
                times = []
                for _ in range(sweep.repeats):
                    clock = time.perf_counter()
                    image = upscale(paint(scene, camera, sw, sh, params, threads=threads).image, w, h)
                    times.append(time.perf_counter() - clock)
                points.append(
                    {
                        "scene": scene_name,
                        "method": method,
                        "spp": spp,
                        "scale": scale,
                        "ms": statistics.median(times) * 1e3,
                        "psnr": psnr(image, reference),
                        "ssim": ssim(image, reference),
                        "psnr_edge": psnr(image, reference, band),
                        "ssim_edge": ssim(image, reference, band),
                        "psnr_inner": psnr(image, reference, ~band),
                    }
                )
    about = {
        "scene": scene_name,
        "params": asdict(base),
        "reference_spp": sweep.reference_spp,
        "reference_ms": reference_ms,
        "reference_floor": floor,
    }
    return points, about


def pareto(points: list[dict], error: str) -> list[dict]:
    """The points no other point beats on both time (lower) and ``error`` (a quality: higher is better)."""
    ordered = sorted(points, key=lambda p: (p["ms"], -p[error]))
    front, best = [], -np.inf
    for p in ordered:
        if p[error] > best:
            front.append(p)
            best = p[error]
    return front


COLORS = {"raytrace": "tab:blue", "image": "tab:orange"}
SHAPES = {1.0: "o", 0.5: "s", 0.25: "^"}
PANELS = (("psnr", "PSNR, whole image (dB)"), ("ssim", "SSIM, whole image"), ("psnr_edge", "PSNR, edge band (dB)"))


def chart(points: list[dict], abouts: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    scenes = [a["scene"] for a in abouts]
    fig, axes = plt.subplots(len(scenes), len(PANELS), figsize=(5.2 * len(PANELS), 3.6 * len(scenes)), squeeze=False)
    for row, about in enumerate(abouts):
        mine = [p for p in points if p["scene"] == about["scene"]]
        for col, (key, label) in enumerate(PANELS):
            ax = axes[row, col]
            for method in CURVES:
                of = [p for p in mine if p["method"] == method]
                for scale, marker in SHAPES.items():
                    at = [p for p in of if p["scale"] == scale]
                    ax.scatter(
                        [p["ms"] for p in at],
                        [p[key] for p in at],
                        c=COLORS[method],
                        marker=marker,
                        s=[18 + 8 * np.log2(p["spp"]) ** 2 for p in at],
                        alpha=0.75,
                        label=f"{method}, scale {scale:g}" if row == col == 0 else None,
                    )
                front = pareto(of, key)
                ax.plot([p["ms"] for p in front], [p[key] for p in front], c=COLORS[method], lw=1.2)
            both = pareto(mine, key)
            ax.scatter(
                [p["ms"] for p in both],
                [p[key] for p in both],
                s=140,
                facecolors="none",
                edgecolors="black",
                lw=1.2,
                label="Pareto front (all)" if row == col == 0 else None,
            )
            for p in both:
                ax.annotate(f"{p['spp']}", (p["ms"], p[key]), textcoords="offset points", xytext=(5, -10), fontsize=7)
            floor = about["reference_floor"].get(key)
            if floor is not None:
                ax.axhline(floor, color="grey", ls=":", lw=1)
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(ScalarFormatter())
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel("time per frame (ms, log)")
            ax.set_ylabel(label)
            ax.set_title(f"{about['scene']}: {label}", fontsize=10)
            ax.grid(alpha=0.3, which="both")
    fig.legend(loc="lower center", ncol=7, fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def run(out: Path, quick: bool = False, threads: int | None = None, scenes=SCENES, sweep: Sweep | None = None) -> dict:
    """Measure, write ``out/accuracy.json`` and ``out/accuracy.png``, print a table; returns the report."""
    sweep = sweep or (QUICK if quick else FULL)
    threads = threads or default_threads()
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    points, abouts = [], []
    for name in scenes:
        mine, about = measure(name, sweep, threads)
        points += mine
        abouts.append(about)
        print(
            f"{name}: reference {sweep.reference_spp} spp in {about['reference_ms'] / 1e3:.1f} s; "
            f"half its samples against it: PSNR {about['reference_floor']['psnr']:.1f} dB"
        )
        print(f"  {'method':13s} {'spp':>4s} {'scale':>5s} {'ms':>8s} {'PSNR':>6s} {'SSIM':>6s} {'edge PSNR':>9s}")
        for p in mine:
            print(
                f"  {p['method']:13s} {p['spp']:4d} {p['scale']:5.2f} {p['ms']:8.1f} {p['psnr']:6.2f} "
                f"{p['ssim']:6.3f} {p['psnr_edge']:9.2f}"
            )
    report = {
        "sweep": asdict(sweep),
        "threads": threads,
        "seconds": time.perf_counter() - started,
        "scenes": abouts,
        "points": points,
        "pareto": {
            a["scene"]: [
                (p["method"], p["spp"], p["scale"])
                for p in pareto([p for p in points if p["scene"] == a["scene"]], "psnr")
            ]
            for a in abouts
        },
    }
    (out / "accuracy.json").write_text(json.dumps(report, indent=1))
    title = (
        f"Speed against accuracy, {sweep.width}x{sweep.height}, {threads} threads; reference: ray traced, "
        f"{sweep.reference_spp} spp (dotted: half its samples); marker size: spp; circled: Pareto front"
    )
    chart(points, abouts, out / "accuracy.png", title)
    print(f"wrote {out / 'accuracy.json'} and {out / 'accuracy.png'} in {report['seconds']:.0f} s")
    return report
