"""The first start: the server answers at once, and says how far it is while, in a thread, the scenes load and
the first scene's kernels compile (about 15 s of one core on a cold numba cache; ``state.Service.start``: the
other scenes' compile after it, while it serves).

Until it is ready, every ``/api/`` request (``/api/health`` included) is answered by :class:`Starting`: a 503
with ``Retry-After`` and a JSON body that says what it is doing (``status`` "starting", ``phase``, ``done`` of
``total`` kernels, and the ``detail`` sentence). A walk-through is refused with the same sentence
(``routes/walk.py``, close code 1013, "try again later"). The client's files are served from the first moment:
the page shows the progress and tries again (``client/main.js``, ``loadScenes``).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable

from starlette.types import ASGIApp, Receive, Scope, Send

RETRY_AFTER_S = 1  # what a caller is told to wait while the server starts: the page shows progress that often

PHASES = ("loading scenes", "compiling kernels", "measuring a walk frame on Ray", "loading uploads")


class Startup:
    """Where a start is: its phase and, while the kernels compile, how many of them are (``kernels`` counts them,
    from another thread: ``painting.warmup.compiled``). Read from the event loop, written by the start's thread."""

    def __init__(self) -> None:
        self.phase = PHASES[0]
        self._ready = threading.Event()
        self._kernels: Callable[[], tuple[int, int]] | None = None

    def enter(self, phase: str, kernels: Callable[[], tuple[int, int]] | None = None) -> None:
        """The start moves on to ``phase``; ``kernels`` tells how many of how many kernels are compiled."""
        assert phase in PHASES, phase
        self.phase, self._kernels = phase, kernels

    def finish(self) -> None:
        self._ready.set()

    @property
    def ready(self) -> bool:
        return self._ready.is_set()

    def progress(self) -> dict:
        """What ``/api/health`` says while starting (JSON)."""
        done, total = self._kernels() if self._kernels is not None else (0, 0)
        return {"status": "starting", "phase": self.phase, "done": done, "total": total, "detail": self.message()}

    def message(self) -> str:
        """One sentence for a caller turned away, such as
        ``the server is starting: compiling kernels (3/14); try again in 1 s``."""
        phase = self.phase
        if self._kernels is not None:
            phase += " ({}/{})".format(*self._kernels())
        return f"the server is starting: {phase}; try again in {RETRY_AFTER_S} s"


class Starting:
    """ASGI middleware: while the start is not over, every ``/api/`` request gets the 503 above (without reaching a
    route: the scenes are not loaded yet, and a painting would wait for the compiler). The client's files and
    the WebSocket pass (the walk-through route refuses with the same sentence, over the socket)."""

    def __init__(self, app: ASGIApp, startup_of: Callable[[], Startup | None]) -> None:
        self.app = app
        self.startup_of = startup_of

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        startup = self.startup_of()
        if scope["type"] != "http" or not scope["path"].startswith("/api/") or startup is None or startup.ready:
            await self.app(scope, receive, send)
            return
        body = json.dumps(startup.progress()).encode()
        headers = [
            (b"content-type", b"application/json"),
            (b"content-length", str(len(body)).encode()),
            (b"retry-after", str(RETRY_AFTER_S).encode()),
            (b"cache-control", b"no-store"),
        ]
        await send({"type": "http.response.start", "status": 503, "headers": headers})
        await send({"type": "http.response.body", "body": body})
