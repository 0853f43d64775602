"""What a connection may hold, and for how long: idle and slow clients cannot starve the service.

uvicorn counts every open connection against its ``limit_concurrency``, idle ones included, and waits
forever for a request's headers, so a few hundred sockets that each send half a request and then wait
turned everyone else away with a plain-text 503. Here instead:

- a request (headers and body) must arrive within ``header_timeout_s`` of the connection opening or of
  the previous response; a connection that is slower gets a 408 and is closed (:class:`GuardedHttp`);
- a client that takes none of a response for ``send_timeout_s`` is closed (behind a kernel send buffer
  capped at :data:`SEND_BUFFER`);
- past ``max_connections`` open connections, the one idle longest (no request in progress) is closed to
  make room, so idle sockets never keep a real client out;
- only requests in progress count against the capacity, ``max_requests`` of them (:class:`Capacity`);
  past it a caller gets a 503 with ``Retry-After`` and a JSON ``detail``, like every other 503 here;
- a body larger than its limit gets a JSON 413 naming the limit (:class:`BodyLimit`), whether its
  ``Content-Length`` says so or its bytes do.

WebSockets that never say hello are the session's to close (``hello_timeout_s``, session.py); until they
do they hold no walk-through place.
"""

from __future__ import annotations

import asyncio
import json
import socket
import time

from starlette.exceptions import HTTPException
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from .settings import Settings

RETRY_AFTER_S = 2  # what a caller turned away for capacity is told to wait: requests in progress end fast
SEND_BUFFER = 256 * 1024
"""The kernel's send buffer of a connection, in bytes. Uncapped, the kernel grows it to megabytes for a client
that stops reading, so a send would wait (and ``send_timeout_s`` run) only seconds of stale data later."""


def _answer(status: int, reason: str, detail: str, **headers: str) -> bytes:
    """A whole HTTP/1.1 response that closes the connection, with a JSON ``detail``."""
    body = json.dumps({"detail": detail}).encode()
    head = [f"HTTP/1.1 {status} {reason}", "content-type: application/json", f"content-length: {len(body)}"]
    head += [f"{name.replace('_', '-')}: {value}" for name, value in headers.items()]
    return ("\r\n".join([*head, "connection: close", "", ""])).encode() + body


class GuardedHttp(HttpToolsProtocol):
    """uvicorn's HTTP protocol with the deadlines and the eviction above. ``settings`` is set on a subclass
    per server (:func:`guarded_http`)."""

    settings: Settings

    def connection_made(self, transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER)
        self.idle_since: float | None = time.monotonic()  # None while a request is in progress
        self.request_timer: asyncio.TimerHandle | None = None
        self.send_timer: asyncio.TimerHandle | None = None
        self._await_request()
        if len(self.connections) > self.settings.max_connections:
            self._make_room()

    def connection_lost(self, exc) -> None:
        self._cancel_timers()
        super().connection_lost(exc)

    # ---- a request must arrive in time ----

    def _await_request(self) -> None:
        self._cancel(self.request_timer)
        self.request_timer = self.loop.call_later(self.settings.header_timeout_s, self._request_late)

    def _request_late(self) -> None:
        self.request_timer = None
        if self.transport.is_closing():
            return
        if self.cycle is None or self.cycle.response_complete:  # no answer begun: say why before closing
            seconds = self.settings.header_timeout_s
            self.transport.write(_answer(408, "Request Timeout", f"no whole request within {seconds:g} s"))
        self.transport.close()  # a request in progress sees a disconnect

    def on_headers_complete(self) -> None:
        self.idle_since = None
        super().on_headers_complete()

    def on_message_complete(self) -> None:
        self._cancel(self.request_timer)
        self.request_timer = None
        super().on_message_complete()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        # kept alive: the next request has the same time to arrive (unless it is here already, pipelined)
        if not self.transport.is_closing() and not self.pipeline and self.cycle.response_complete:
            self.idle_since = time.monotonic()
            self._await_request()

    def handle_websocket_upgrade(self) -> None:
        self._cancel_timers()  # the WebSocket's own limits take over (hello_timeout_s, send_timeout_s)
        super().handle_websocket_upgrade()

    # ---- a response must be taken in time ----

    def pause_writing(self) -> None:
        super().pause_writing()
        self._cancel(self.send_timer)
        self.send_timer = self.loop.call_later(self.settings.send_timeout_s, self.transport.abort)

    def resume_writing(self) -> None:
        super().resume_writing()
        self._cancel(self.send_timer)
        self.send_timer = None

    # ---- room for real clients ----

    def _make_room(self) -> None:
        """Close the connection idle longest; if none is idle, this new one, with a 503."""
        others = [c for c in self.connections if isinstance(c, GuardedHttp) and c is not self]
        idle = [c for c in others if c.idle_since is not None]
        if idle:
            min(idle, key=lambda c: c.idle_since or 0.0).transport.close()
            return
        limit = self.settings.max_connections
        detail = f"the server has its {limit} connections busy; try again shortly"
        self.transport.write(_answer(503, "Service Unavailable", detail, retry_after=str(RETRY_AFTER_S)))
        self.transport.close()

    def _cancel_timers(self) -> None:
        self._cancel(self.request_timer)
        self._cancel(self.send_timer)
        self.request_timer = self.send_timer = None

    @staticmethod
    def _cancel(timer: asyncio.TimerHandle | None) -> None:
        if timer is not None:
            timer.cancel()


def guarded_http(settings: Settings) -> type[GuardedHttp]:
    """The HTTP protocol class for uvicorn's ``http=``, with these settings."""
    return type("GuardedHttp", (GuardedHttp,), {"settings": settings})


class Capacity:
    """ASGI middleware: at most ``limit`` HTTP requests in progress; past it, 503 with ``Retry-After`` and a
    JSON ``detail`` (uvicorn's own limit answers in plain text and counts idle connections)."""

    def __init__(self, app: ASGIApp, limit: int):
        self.app, self.limit = app, limit
        self.in_progress = 0

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        if self.in_progress >= self.limit:
            detail = f"the server has {self.limit} requests in progress, its limit; try again shortly"
            response = JSONResponse({"detail": detail}, 503, headers={"Retry-After": str(RETRY_AFTER_S)})
            return await response(scope, receive, send)
        self.in_progress += 1
        try:
            await self.app(scope, receive, send)
        finally:
            self.in_progress -= 1


class TooLarge(HTTPException):
    """A request body past its limit, raised from the body's ``receive`` (the route's body parsing passes an
    ``HTTPException`` on to the app's handlers, which answer it in JSON)."""

    def __init__(self, limit: int, what: str, setting: str):
        super().__init__(413, f"{what} is larger than the {limit:,} bytes this server takes ({setting})")


class BodyLimit:
    """ASGI middleware: the one limit on request bodies, ``limit`` bytes (``max_body_bytes``), or the larger one
    ``larger`` gives a path (uploads). A ``Content-Length`` past it is answered at once, a body that grows
    past it as soon as it does; both with a JSON 413 that names the limit and its setting."""

    def __init__(self, app: ASGIApp, limit: int, larger: dict[str, tuple[int, str, str]]):
        self.app = app
        self.limit = (limit, "the body", "RCP_MAX_BODY_BYTES")
        self.larger = larger  # path -> (limit, what is limited, its setting)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        limit, what, setting = self.larger.get(scope["path"], self.limit)
        too_large = TooLarge(limit, what, setting)
        declared = next((value for name, value in scope["headers"] if name == b"content-length"), b"")
        if declared.isdigit() and int(declared) > limit:
            return await _too_large(too_large)(scope, receive, send)
        received, started = 0, False

        async def counted() -> Message:
            nonlocal received
            message = await receive()
            received += len(message.get("body", b""))
            if received > limit:
                raise too_large
            return message

        async def watched(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted, watched)
        except TooLarge:  # past the route's own handling (a body read outside it): still a 413, not a fault
            if started:
                raise
            await _too_large(too_large)(scope, receive, send)


def _too_large(exc: TooLarge) -> JSONResponse:
    return JSONResponse({"detail": exc.detail}, 413, headers={"Connection": "close"})
