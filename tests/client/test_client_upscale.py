"""The walk frame's upscale (client/upscale.js, EASU in WebGL2) in a real headless Chromium with software WebGL:
a small painting drawn on the full-size canvas is closer to the full-size painting of the same camera when
drawn "sharp" than when drawn "smooth" (the 2D canvas's smoothing) or scaled bilinearly (here, in numpy), in
PSNR and in the gradient-magnitude error (how far its edges are from the full painting's). The panel's choice
is kept across a reload.
"""

from __future__ import annotations

import base64
import io
import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from ..service.conftest import decode, post
from .conftest import CHROMIUM, SOFTWARE_WEBGL, chromium

CANVAS = (1280, 720)  # the full painting's size: the canvas the walk frames are drawn on
WALK_SIZES = [(320, 180), (640, 360)]  # today's walk frame, and the one aimed at
JPEG_QUALITY = 80  # the walk's (client/main.js)
WAIT_MS = 60_000

pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason=f"no Chromium at {CHROMIUM} (CI installs it)")

# a frame pushed as the connection would (its JPEG's bytes after a `frame` message), drawn once decoded
PUSH = """async ([b64, probe]) => {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  rcp.frames.push({ ...rcp.overlay.frame, probe }, bytes.buffer);
  while (rcp.overlay.frame?.probe !== probe) await new Promise((r) => setTimeout(r, 20));
  return rcp.frames.upscaler.draws;
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
    """Mean absolute difference of the gradient magnitudes: soft edges and staircases both raise it."""
    return float(np.abs(gradient(image) - gradient(reference)).mean())


def test_a_walk_frame_drawn_sharp_is_closer_to_the_full_painting_than_bilinear_and_the_choice_is_kept(
    browser, live_server, tmp_path
):
    full = decode(render(live_server, *CANVAS, format="png"))
    context = browser.new_context(viewport={"width": 1024, "height": 576})
    page = context.new_page()
    problems = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(f"{live_server.url}/?scene=default&width=320&height=180")
    page.wait_for_function("rcp.overlay.frame && rcp.overlay.frame.final", timeout=WAIT_MS)
    assert page.input_value("#walk-quality") == "auto"
    assert page.evaluate("rcp.frames.upscaler.problem") is None  # WebGL2 there (software)
    page.evaluate(f"rcp.connection.stop(); rcp.frames.resize({CANVAS[0]}, {CANVAS[1]})")  # our frames only now

    figures = {}
    look = Path(os.environ.get("RCP_LOOK_DIR", tmp_path))
    for k, (width, height) in enumerate(WALK_SIZES):
        jpeg = render(live_server, width, height, format="jpeg", quality=JPEG_QUALITY)
        drawn, draws = {}, []
        for n, quality in enumerate(("sharp", "smooth", "auto")):
            page.select_option("#walk-quality", quality)
            draws.append(page.evaluate(PUSH, [base64.b64encode(jpeg).decode(), 10 * k + n]))
            drawn[quality] = canvas(page)
        assert draws[1] == draws[0] and draws[2] == draws[0] + 1  # smooth never draws with EASU, auto does here
        assert np.array_equal(drawn["auto"], drawn["sharp"])
        drawn["bilinear"] = bilinear(decode(jpeg), *CANVAS)
        figures[width] = {name: (psnr(image, full), edge_error(image, full)) for name, image in drawn.items()}
        for name, (db, edge) in figures[width].items():
            print(
                f"{width}x{height} -> {CANVAS[0]}x{CANVAS[1]} {name:8s} PSNR {db:6.2f} dB  gradient error {edge:5.2f}"
            )
        sharp_db, sharp_edge = figures[width]["sharp"]
        for baseline in ("smooth", "bilinear"):
            assert sharp_db > figures[width][baseline][0], (width, baseline, figures[width])
            assert sharp_edge < figures[width][baseline][1], (width, baseline, figures[width])
        # to look at: a crop of each, side by side with the full painting's
        crop = np.s_[200:520, 380:900]
        side = np.concatenate([full[crop], drawn["sharp"][crop], drawn["smooth"][crop]], axis=1)
        Image.fromarray(side).save(look / f"upscale-{width}.png")

    # ---- the choice is kept in this browser ----
    page.select_option("#walk-quality", "smooth")
    page.reload()
    page.wait_for_function("window.rcp !== undefined", timeout=WAIT_MS)
    assert page.input_value("#walk-quality") == "smooth"
    assert page.evaluate("rcp.frames.upscaler.quality") == "smooth"
    context.close()
    assert problems == [], problems
