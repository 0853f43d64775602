"""A real server in a background thread on a free loopback port, for benchmarks and tests."""

from __future__ import annotations

import socket
import threading
import time

from .app import Server
from .settings import Settings


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class BackgroundServer:
    """``rcp serve`` in a thread: uvicorn on 127.0.0.1 and a free port. Use it as a context manager."""

    def __init__(self, **settings):
        self.settings = Settings(host="127.0.0.1", port=free_port(), **settings)
        self.server = Server(self.settings, log_level="warning")
        self.app = self.server.config.app
        self.url = f"http://127.0.0.1:{self.settings.port}"
        self.ws_url = f"ws://127.0.0.1:{self.settings.port}/ws"
        self._thread = threading.Thread(target=self.server.run, name="rcp-server", daemon=True)

    def __enter__(self) -> BackgroundServer:
        self._thread.start()
        deadline = time.monotonic() + 120  # a first start may compile the kernels
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the server did not start")
            time.sleep(0.05)
        return self

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self._thread.join(30)
