"""The walk frame's upscale (client/upscale.js, EASU in WebGL2) in a real headless Chromium with software WebGL.

A small painting drawn on the full-size canvas "sharp" is this file's numpy port of the shader to within one
level in 255 (a flipped row, a half-pixel shift or a swapped tap fails), and it is closer to the full-size
painting of the same camera than the same frame drawn "smooth" (the 2D canvas's smoothing) or scaled
bilinearly (here, in numpy): in PSNR, and at the full painting's edges in gradient magnitude (soft edges and
staircases both raise that error). The panel's choice is kept across a reload.
"""

from __future__ import annotations

import base64
import io
import os
from pathlib import Path

import numpy as np
import pytest
from helpers.browser import SOFTWARE_WEBGL, chromium, needs_chromium
from helpers.wire import decode, post
from PIL import Image

CANVAS = (1280, 720)  # the full painting's size: the canvas the walk frames are drawn on
WALK_SIZES = [(320, 180), (640, 360)]  # today's walk frame, and the one aimed at
JPEG_QUALITY = 70  # a walk frame's (service/planner.py WALK_QUALITY)
LAMBDA_P = 12.0  # the default scene's smudge, in pixels of the painting

# (name, the full painting's settings, the walk frame's, given its width). lambda_p counts pixels, so a frame a
# quarter as wide smudges four times as far across the picture: the same painting at another size scales it.
PAINTINGS = [
    ("plain render", lambda width: {"lambda_p": 0.0}),
    ("painting", lambda width: {"lambda_p": LAMBDA_P * width / CANVAS[0]}),
]
WAIT_MS = 60_000

pytestmark = needs_chromium

# a frame pushed as the connection would (its JPEG's bytes after a `frame` message), drawn once decoded
PUSH = """async ([b64, probe]) => {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  const before = rcp.frames.upscaler.draws;
  rcp.frames.push({ ...rcp.overlay.frame, probe }, bytes.buffer);
  while (rcp.overlay.frame?.probe !== probe) await new Promise((r) => setTimeout(r, 20));
  return rcp.frames.upscaler.draws - before;  // the frame went through EASU: 1, or not: 0
}"""


@pytest.fixture(scope="module")
def browser():
    with chromium(*SOFTWARE_WEBGL) as launched:
        yield launched


def render(server, width: int, height: int, **options) -> bytes:
    body = {"scene": "default", "width": width, "height": height, **options}
    answer = post(server, body)
    assert answer.status_code == 200, answer.text
    return answer.content


def canvas(page) -> np.ndarray:
    url = page.evaluate("rcp.canvas.toDataURL('image/png')")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))


def bilinear(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` scaled to ``width x height`` bilinearly, pixel centres on pixel centres, edges clamped."""
    h, w = image.shape[:2]
    x = np.clip((np.arange(width) + 0.5) * w / width - 0.5, 0, w - 1)
    y = np.clip((np.arange(height) + 0.5) * h / height - 0.5, 0, h - 1)
    x0, y0 = np.minimum(x.astype(int), w - 2), np.minimum(y.astype(int), h - 2)
    fx, fy = (x - x0)[None, :, None], (y - y0)[:, None, None]
    a = image.astype(np.float64)
    top = a[y0][:, x0] * (1 - fx) + a[y0][:, x0 + 1] * fx
    bottom = a[y0 + 1][:, x0] * (1 - fx) + a[y0 + 1][:, x0 + 1] * fx
    return np.clip(np.rint(top * (1 - fy) + bottom * fy), 0, 255).astype(np.uint8)


def easu(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` scaled to ``width x height`` as client/upscale.js's shader does, in numpy (its reference)."""
    src = image.astype(np.float64) / 255
    h, w = src.shape[:2]
    x, y = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    px, py = x * w / width - 0.5, y * h / height - 0.5
    ox, oy = np.floor(px).astype(int), np.floor(py).astype(int)
    px, py = px - ox, py - oy
    offsets = {"b": (0, -1), "c": (1, -1), "e": (-1, 0), "f": (0, 0), "g": (1, 0), "h": (2, 0)}
    offsets |= {"i": (-1, 1), "j": (0, 1), "k": (1, 1), "l": (2, 1), "n": (0, 2), "q": (1, 2)}
    taps = {key: src[np.clip(oy + dy, 0, h - 1), np.clip(ox + dx, 0, w - 1)] for key, (dx, dy) in offsets.items()}
    luma = {key: t[..., 2] * 0.5 + t[..., 0] * 0.5 + t[..., 1] for key, t in taps.items()}

    # ---- the edge ----
    dir_x, dir_y, strength = np.zeros_like(px), np.zeros_like(px), np.zeros_like(px)
    for weight, (a, b, c, d, e) in [
        ((1 - px) * (1 - py), "befgj"),
        (px * (1 - py), "cfghk"),
        ((1 - px) * py, "fijkn"),
        (px * py, "gjklq"),
    ]:
        a, b, c, d, e = (luma[key] for key in (a, b, c, d, e))
        along_x = np.clip(np.abs(d - b) / np.maximum(np.maximum(np.abs(d - c), np.abs(c - b)), 1e-6), 0, 1)
        along_y = np.clip(np.abs(e - a) / np.maximum(np.maximum(np.abs(e - c), np.abs(c - a)), 1e-6), 0, 1)
        dir_x, dir_y = dir_x + (d - b) * weight, dir_y + (e - a) * weight
        strength += (along_x**2 + along_y**2) * weight
    norm2 = dir_x**2 + dir_y**2
    flat = norm2 < 1 / 32768
    scale = 1 / np.sqrt(np.where(flat, 1, norm2))
    dir_x, dir_y = np.where(flat, 1, dir_x * scale), np.where(flat, 0, dir_y * scale)
    strength = (0.5 * strength) ** 2

    # ---- the kernel ----
    stretch = 1 / np.maximum(np.abs(dir_x), np.abs(dir_y))
    len_x, len_y = 1 + (stretch - 1) * strength, 1 - 0.5 * strength
    lob = 0.5 + (0.25 - 0.04 - 0.5) * strength
    total, weighted = np.zeros_like(px), np.zeros_like(taps["f"])
    for key, (dx, dy) in offsets.items():
        off_x, off_y = dx - px, dy - py
        vx, vy = (off_x * dir_x + off_y * dir_y) * len_x, (off_y * dir_x - off_x * dir_y) * len_y
        d2 = np.minimum(vx * vx + vy * vy, 1 / lob)
        weight = (1.5625 * (0.4 * d2 - 1) ** 2 - 0.5625) * (lob * d2 - 1) ** 2
        weighted += taps[key] * weight[..., None]
        total += weight
    f, g, j, k = taps["f"], taps["g"], taps["j"], taps["k"]
    sharp = np.clip(weighted / total[..., None], np.minimum.reduce([f, g, j, k]), np.maximum.reduce([f, g, j, k]))
    smooth = (f * (1 - px[..., None]) + g * px[..., None]) * (1 - py[..., None])
    smooth += (j * (1 - px[..., None]) + k * px[..., None]) * py[..., None]
    out = smooth + (sharp - smooth) * strength[..., None]
    return np.clip(np.rint(out * 255), 0, 255).astype(np.uint8)


def psnr(image: np.ndarray, reference: np.ndarray) -> float:
    mse = np.mean((image.astype(np.float64) - reference.astype(np.float64)) ** 2)
    return float(10 * np.log10(255.0**2 / mse))


def gradient(image: np.ndarray) -> np.ndarray:
    """Sobel gradient magnitude of the luma, (h-2, w-2), in 0..255 units a pixel."""
    y = image.astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    gx = (y[:-2, 2:] + 2 * y[1:-1, 2:] + y[2:, 2:] - y[:-2, :-2] - 2 * y[1:-1, :-2] - y[2:, :-2]) / 8
    gy = (y[2:, :-2] + 2 * y[2:, 1:-1] + y[2:, 2:] - y[:-2, :-2] - 2 * y[:-2, 1:-1] - y[:-2, 2:]) / 8
    return np.hypot(gx, gy)


def edge_error(image: np.ndarray, reference: np.ndarray) -> float:
    """Mean absolute difference of the gradient magnitudes at the reference's edges (its steepest tenth of
    pixels): a soft edge is less steep, a staircase steep in the wrong places."""
    steep = gradient(reference)
    edges = steep > np.percentile(steep, 90)
    return float(np.abs(gradient(image)[edges] - steep[edges]).mean())


def gradient_error(image: np.ndarray, reference: np.ndarray) -> float:
    """The same over every pixel (flat areas too, where a JPEG's noise counts)."""
    return float(np.abs(gradient(image) - gradient(reference)).mean())


def test_a_walk_frame_drawn_sharp_is_closer_to_the_full_painting_than_bilinear_and_the_choice_is_kept(
    browser, live_server, tmp_path
):
    context = browser.new_context(viewport={"width": 1024, "height": 576})
    page = context.new_page()
    problems = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(f"{live_server.url}/?scene=default&width=320&height=180")
    page.wait_for_function("rcp.overlay.frame && rcp.overlay.frame.final", timeout=WAIT_MS)
    assert page.input_value("#walk-quality") == "auto"
    assert page.evaluate("rcp.frames.upscaler.problem") is None  # WebGL2 there (software)
    accelerated = page.evaluate("rcp.frames.upscaler.accelerated")
    assert accelerated is False  # SwiftShader: "auto" leaves the upscale to machines with a GPU
    page.evaluate(f"rcp.connection.stop(); rcp.frames.resize({CANVAS[0]}, {CANVAS[1]})")  # our frames only now

    look = Path(os.environ.get("TEST_LOOK_DIR", tmp_path))
    probe = 0
    for name, paint in PAINTINGS:
        full = decode(render(live_server, *CANVAS, format="png", paint=paint(CANVAS[0])))
        for width, height in WALK_SIZES:
            jpeg = render(live_server, width, height, format="jpeg", quality=JPEG_QUALITY, paint=paint(width))
            drawn, draws = {}, []
            for quality in ("sharp", "smooth", "auto"):
                page.select_option("#walk-quality", quality)
                probe += 1
                draws.append(page.evaluate(PUSH, [base64.b64encode(jpeg).decode(), probe]))
                drawn[quality] = canvas(page)
            assert draws == [1, 0, int(accelerated)]  # smooth never draws with EASU; auto on a GPU only
            assert np.array_equal(drawn["auto"], drawn["sharp" if accelerated else "smooth"])
            reference = easu(decode(jpeg), *CANVAS)
            assert np.abs(drawn["sharp"].astype(int) - reference).max() <= 1  # the shader is its numpy port
            drawn["bilinear"] = bilinear(decode(jpeg), *CANVAS)
            figures = {
                kind: (psnr(im, full), edge_error(im, full), gradient_error(im, full)) for kind, im in drawn.items()
            }
            for kind, (db, edge, grad) in figures.items():
                print(
                    f"{name:12s} {width}x{height} {kind:8s} PSNR {db:6.2f} dB  edges {edge:5.2f}  gradient {grad:5.2f}"
                )
            # to look at: a crop of each, side by side: the full painting, sharp, smooth
            crop = np.s_[220:460, 440:840]
            side = np.concatenate([full[crop], drawn["sharp"][crop], drawn["smooth"][crop]], axis=1)
            Image.fromarray(side).save(look / f"upscale-{name.split()[0]}-{width}.png")
            for baseline in ("smooth", "bilinear"):
                # with full-resolution color (4:4:4) the sharp frame's PSNR is the bilinear one's within 0.1 dB (it
                # beat it by 0.03-0.05 dB over 4:2:0): its gain is at the edges, below
                assert figures["sharp"][0] > figures[baseline][0] - 0.1, (name, width, baseline, figures)
                assert figures["sharp"][1] < figures[baseline][1], (name, width, baseline, figures)

    # ---- the choice is kept in this browser ----
    page.select_option("#walk-quality", "smooth")
    page.reload()
    page.wait_for_function("window.rcp !== undefined", timeout=WAIT_MS)
    assert page.input_value("#walk-quality") == "smooth"
    assert page.evaluate("rcp.frames.upscaler.quality") == "smooth"
    context.close()
    assert problems == [], problems
