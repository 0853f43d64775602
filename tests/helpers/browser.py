"""The browser the client's tests drive: Debian's Chromium through Playwright, and the one skip where it is
missing."""

from __future__ import annotations

import base64
import contextlib
import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

CHROMIUM = Path("/usr/bin/chromium")  # Debian's package (.ci/run installs it), driven by Playwright
CHROMIUM_ARGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)
SOFTWARE_WEBGL = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader")  # the same pixels on every machine


@contextlib.contextmanager
def chromium(*extra: str):
    """A headless Chromium for the client's tests (``extra``: more command-line switches)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=[*CHROMIUM_ARGS, *extra])
        yield browser
        browser.close()


needs_chromium = pytest.mark.skipif(not CHROMIUM.exists(), reason="needs Debian's chromium at /usr/bin/chromium")
"""The one skip of every test that drives the browser (``pytestmark = needs_chromium``)."""

# ---- the client in a page ----

SIZE = (480, 270)  # the painting's size (small: fast frames); the window is larger, so the panel is open
WINDOW = (1024, 576)
WAIT_MS = 30_000  # two shared cores: a refined frame may take a few seconds under load
WAIT_360_MS = 60_000  # a panorama costs about as much as the flat painting, drawn in software WebGL besides


@contextlib.contextmanager
def client(browser, url: str, scene: str = "default", wait: bool = True, touch: bool = False, fragment: str = ""):
    """The client on ``scene`` (its first refined frame shown unless ``wait`` is false); fails on console errors."""
    viewport = {"width": WINDOW[0], "height": WINDOW[1]}
    context = browser.new_context(viewport=viewport, accept_downloads=True, has_touch=touch)
    page = context.new_page()
    problems = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(f"{url}/?scene={scene}&width={SIZE[0]}&height={SIZE[1]}{fragment}")
    if wait:
        wait_final(page)
    try:
        yield page
    finally:
        context.close()
    assert problems == [], f"console errors: {problems}"


def wait_final(page, after_seq: int = 0, camera_id: int | None = None, current: bool = False) -> dict:
    """Wait for a frame at rest (fully refined) newer than ``after_seq`` (showing ``camera_id``, or with
    ``current`` the camera last sent); its description."""
    page.wait_for_function(
        """([seq, id, current]) => { const f = rcp.overlay.frame;
            const want = current ? rcp.state.cameraId : id;
            return f && f.final && f.seq > seq && (want === null || f.camera_id === want); }""",
        arg=[after_seq, camera_id, current],
        timeout=WAIT_MS,
    )
    return page.evaluate("rcp.overlay.frame")


def canvas(page) -> np.ndarray:
    """The canvas's pixels: (height, width, 3) uint8."""
    url = page.evaluate("rcp.canvas.toDataURL('image/png')")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))


def difference(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.int16) - b.astype(np.int16)).mean())


def sent(page, kind: str | None = None) -> list[dict]:
    return page.evaluate("([kind]) => rcp.sent.filter((m) => kind === null || m.type === kind)", [kind])


def click_view(page, x: int, y: int) -> None:
    """A click (no drag) on pixel (x, y) of the painting, wherever the canvas shows it."""
    box = page.locator("#view").bounding_box()
    page.mouse.click(box["x"] + (x + 0.5) * box["width"] / SIZE[0], box["y"] + (y + 0.5) * box["height"] / SIZE[1])


def set_slider(page, field: str, value: float) -> None:
    page.locator(f'[data-field="{field}"] input[type=range]').fill(str(value))


@contextlib.contextmanager
def client_360(browser, url: str, scene: str = "default", init_script: str | None = None):
    """The client on ``scene``, its first refined frame shown; ``page.ws_sent`` lists every WebSocket message
    the page sent, as the browser saw it go. Fails on console errors."""
    context = browser.new_context(viewport={"width": WINDOW[0], "height": WINDOW[1]}, accept_downloads=True)
    if init_script:
        context.add_init_script(init_script)
    page = context.new_page()
    problems: list[str] = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    frames_sent: list = []
    page.on("websocket", lambda ws: ws.on("framesent", lambda payload: frames_sent.append(payload)))
    page.ws_sent = frames_sent  # type: ignore[attr-defined]
    page.goto(f"{url}/?scene={scene}&width={SIZE[0]}&height={SIZE[1]}")
    page.wait_for_function("rcp.overlay.frame && rcp.overlay.frame.final", timeout=WAIT_360_MS)
    try:
        yield page
    finally:
        context.close()
    assert problems == [], f"console errors: {problems}"


def data_url_image(url: str) -> np.ndarray:
    """A data URL's PNG as (height, width, 3) float64."""
    data = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(np.float64)


def fresh_page(browser, url: str, **options):
    """A new browser context (nothing remembered) opened at ``url``; returns (context, page, console errors)."""
    context = browser.new_context(viewport={"width": 1024, "height": 576}, **options)
    page = context.new_page()
    problems: list[str] = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(url)
    return context, page, problems
