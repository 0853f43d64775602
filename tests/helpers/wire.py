"""Clients of a real server's wire: a render over REST, a walk over the WebSocket, and the pictures they get."""

from __future__ import annotations

import contextlib
import io
import json

import httpx
import numpy as np
from PIL import Image
from websockets.sync.client import connect


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
