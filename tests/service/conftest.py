"""A real server on loopback for the service's tests, and a WebSocket client that reads its frames."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image
from websockets.sync.client import connect

from rcp_server.bench.harness import BackgroundServer

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


@pytest.fixture(scope="session")
def live_server():
    """One real server per test process (settles fast, so refinement starts soon after the camera rests)."""
    with BackgroundServer(settle_ms=80) as server:
        yield server


def post(server, body: dict) -> httpx.Response:
    """``POST /api/render`` of ``body``."""
    return httpx.post(f"{server.url}/api/render", json=body, timeout=120)


def decode(data: bytes) -> np.ndarray:
    """A PNG or JPEG from the server, as (height, width, 3) uint8."""
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


class Walk:
    """A WebSocket client of a real server that reads frames as (meta, image)."""

    def __init__(self, server, path: str = "", **options):
        self._stack = contextlib.ExitStack()
        options = {"max_size": None, "open_timeout": 30, **options}
        self.ws = self._stack.enter_context(connect(server.ws_url + path, **options))

    def send(self, **message) -> None:
        self.ws.send(json.dumps(message))

    def next(self, timeout: float = 30.0) -> dict:
        return json.loads(self.ws.recv(timeout))

    def frame(self, timeout: float = 30.0) -> tuple[dict, np.ndarray]:
        while (meta := self.next(timeout))["type"] != "frame":
            assert meta["type"] != "error", meta
        image = self.ws.recv(timeout)
        assert isinstance(image, bytes)
        return meta, decode(image)

    def until_final(self, timeout: float = 60.0) -> list[tuple[dict, np.ndarray]]:
        frames = []
        while not frames or not frames[-1][0]["final"]:
            frames.append(self.frame(timeout))
        return frames

    def close(self) -> None:
        self._stack.close()


@pytest.fixture
def walk_to():
    """Opens walk-throughs (``walk_to(server)``); all are closed after the test."""
    opened: list[Walk] = []

    def open_walk(server, path: str = "", **options) -> Walk:
        opened.append(Walk(server, path, **options))
        return opened[-1]

    yield open_walk
    for client in opened:
        client.close()


@pytest.fixture
def walk(live_server, walk_to):
    return walk_to(live_server)
