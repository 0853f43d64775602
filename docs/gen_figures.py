"""The headline tables of the Figures pages, generated from what the benchmarks write when the site is built.

``rcp bench accuracy --out docs`` writes ``docs/accuracy.json`` and ``rcp bench stability --out docs`` writes
``docs/stability.json``. A page says where a table goes with a line of its own, and this MkDocs hook (``hooks:``
in ``mkdocs.yml``) writes the table there from the JSON, so running the benchmark again and building the site
is all it takes to bring a page up to date:

- ``<!-- figures: accuracy -->``: time per frame and error of both methods, by scene and samples per pixel;
- ``<!-- figures: stability -->``: where each method breaks, probe by probe.

``python docs/gen_figures.py`` prints both tables.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

DOCS = Path(__file__).resolve().parent
MARKER = re.compile(r"^<!-- figures: (accuracy|stability) -->$", re.MULTILINE)


def accuracy_table(run: dict[str, Any]) -> str:
    """Full resolution, the fewest and the most samples per pixel, both methods: milliseconds a frame, PSNR and
    SSIM against the converged reference, PSNR of the edge band, and whether the point is on the Pareto front
    (no other point of its scene both faster and closer)."""
    spps = run["sweep"]["spps"]
    ends = (min(spps), max(spps))
    rows = [
        "| scene | method | spp | ms a frame | PSNR (dB) | SSIM | edge-band PSNR (dB) | on the front |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for scene in run["scenes"]:
        name = scene["scene"]
        front = {(m, s, sc) for m, s, sc in run["pareto"][name]}
        chosen = [p for p in run["points"] if p["scene"] == name and p["scale"] == 1.0 and p["spp"] in ends]
        for p in sorted(chosen, key=lambda p: (p["spp"], p["method"] != "raytrace")):
            on_front = "yes" if (p["method"], p["spp"], p["scale"]) in front else ""
            rows.append(
                f"| `{name}` | {p['method']} | {p['spp']} | {p['ms']:.1f} | {p['psnr']:.2f} | {p['ssim']:.3f} "
                f"| {p['psnr_edge']:.2f} | {on_front} |"
            )
        floor = scene["reference_floor"]
        rows.append(
            f"| `{name}` | reference, half its samples | {scene['reference_spp'] // 2} | "
            f"| {floor['psnr']:.2f} | {floor['ssim']:.3f} | {floor['psnr_edge']:.2f} | |"
        )
    return "\n".join(rows)


def stability_table(run: dict[str, Any]) -> str:
    """One row a probe: what the ray-traced painting does, what the image method does."""
    edges = run["edges"]
    eye = run["eye_displacement"]
    lambdas = run["extremes"]["lambda_p"]
    largest = max(lambdas, key=float)
    far = lambdas[largest]
    grazing = run["extremes"]["grazing"]
    thin = run["extremes"]["thin_geometry"]
    conv = run["convergence"]
    pan = run["temporal"]["runs"]
    inside = edges["mirror"]["iteration2"]["change_inner"]
    by_edge = ", ".join(
        f"{mode} {edges[mode]['iteration2']['change_edge']:.4f}" for mode in ("clamp", "wrap", "mirror")
    )
    both = all(lambdas[k][m]["finite"] and lambdas[k][m]["in_range"] for k in lambdas for m in ("raytrace", "image"))
    rows = [
        "| probe | ray traced | image method |",
        "|---|---|---|",
        f"| screen edges: error a channel in the outer 8% after the first lookup (inside: {inside:.4f}) "
        f"| the reference | {by_edge} |",
        f"| eyes that move (`lambda_e` {eye['lambda_e']:g}) | right by construction | cannot: the closest "
        f"(`lambda_e` 0) is {eye['psnr']:.1f} dB off, {eye['change_near_silhouettes']:.3f} a channel near "
        f"silhouettes, {eye['change_elsewhere']:.3f} elsewhere |",
        f"| `lambda_p` up to {largest} px | {'finite and in range' if both else 'NOT finite or in range'}, "
        f"{far['raytrace']['rays_leaving_scene']:.0%} of rays leave the scene at {largest} | "
        f"{far['image']['lookups_off_screen']:.0%} of lookups off screen, "
        f"{far['image']['psnr_against_raytrace']:.1f} dB against ray tracing (at 1 px: "
        f"{lambdas[min(lambdas, key=float)]['image']['psnr_against_raytrace']:.1f} dB) |",
        f"| grazing view (0.05 above a plane) | finite | {grazing['image']['psnr_against_raytrace']:.1f} dB "
        f"against ray tracing |",
        f"| thin poles (a sixth of a pixel), 1 spp | {thin['spp1']['raytrace_pole_fraction']:.2%} of pixels "
        f"show them | {thin['spp1']['image_pole_fraction']:.2%} (the plain render saw "
        f"{thin['spp1']['plain_pole_fraction']:.2%}) |",
        f"| change an iteration: 2nd, 6th, {len(conv['raytrace']) + 1}th | "
        + " | ".join(f"{c[0]:.3f}, {c[4]:.3f}, {c[-1]:.3f}" for c in (conv["raytrace"], conv["image"]))
        + " |",
        f"| slow pan, flicker a frame beyond the plain render's {_mean(run['temporal']['plain_change']):.3f}: "
        "per frame / temporal | "
        + " | ".join(
            f"{_mean(pan[f'{m} per-frame']['flicker']):.4f} / {_mean(pan[f'{m} temporal']['flicker']):.4f}"
            for m in ("raytrace", "image")
        )
        + " |",
        f"| smudges {run['temporal']['lag']} frames apart, correlation with the scene / with the screen "
        f"(per frame) | {pan['raytrace per-frame']['smudge_with_scene']:.2f} / "
        f"{pan['raytrace per-frame']['smudge_with_screen']:.2f} | "
        f"{pan['image per-frame']['smudge_with_scene']:.2f} / {pan['image per-frame']['smudge_with_screen']:.2f} |",
    ]
    return "\n".join(rows)


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)


TABLES = {"accuracy": accuracy_table, "stability": stability_table}


def expand(markdown: str, docs: Path = DOCS) -> str:
    """``markdown`` with each figures marker replaced by its table, from the JSON the benchmark last wrote."""
    return MARKER.sub(lambda m: TABLES[m.group(1)](json.loads((docs / f"{m.group(1)}.json").read_text())), markdown)


def on_page_markdown(markdown: str, **_: Any) -> str:
    """The MkDocs hook: every page's Markdown, markers expanded."""
    return expand(markdown)


if __name__ == "__main__":
    for name, table in TABLES.items():
        print(table(json.loads((DOCS / f"{name}.json").read_text())), end="\n\n")
