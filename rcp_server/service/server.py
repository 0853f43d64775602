"""uvicorn serving the app (``rcp serve``): the transport's limits, a capped send buffer, a stop that loses
no answer."""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable

import uvicorn
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from .access import HideTokens
from .app import create_app
from .guard import SEND_BUFFER, guarded_http
from .settings import Settings
from .state import Service, service_of

log = logging.getLogger("rcp.service")


class CappedWebSockets(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol with the kernel's send buffer capped: the kernel would otherwise grow it to
    megabytes for a client that stops reading, holding seconds of stale frames before a send ever waits. With
    the cap, sends wait after ``SEND_BUFFER`` bytes and newer frames replace the unsent one (session.py)."""

    SEND_BUFFER = SEND_BUFFER

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.SEND_BUFFER)


class Server(uvicorn.Server):
    """uvicorn serving the app, with the transport's own limits: WebSocket messages (past this, the connection
    closes with 1009; the session's own, smaller limit answers with an error first), deadlines for idle and
    slow connections and room for real ones (guard.py; uvicorn's ``limit_concurrency`` is not used: it counts
    idle connections and answers in plain text), and a stop that loses no answer.

    On SIGINT or SIGTERM, requests and walk-throughs in flight get ``stop_grace_s`` (a setting) to finish; then
    their paintings are stopped, so each caller is told "the server is stopping" (503) before uvicorn's own
    grace, ``ANSWER_S`` longer, runs out and cancels whatever is left (a 500 and a traceback). A second signal
    stops the paintings at once; a third Ctrl-C is uvicorn's forced exit."""

    ANSWER_S = 4  # after the paintings are stopped, the time their callers have to be told so

    def __init__(self, settings: Settings, listening: Callable[[], None] | None = None, **options):
        self.app = create_app(settings)
        config = uvicorn.Config(
            self.app,
            host=settings.host,
            port=settings.port,
            ws=CappedWebSockets,
            http=guarded_http(settings),  # deadlines for idle and slow clients, room for real ones (guard.py)
            ws_max_size=64 * settings.max_message_bytes,
            ws_per_message_deflate=False,  # frames are JPEGs: deflating them costs CPU and saves nothing
            timeout_graceful_shutdown=settings.stop_grace_s + self.ANSWER_S,
            **options,
        )
        for name in ("uvicorn.error", "uvicorn.access"):
            logging.getLogger(name).addFilter(HideTokens())
        self.settings = settings
        self.listening = listening  # called once the port answers (``rcp serve`` says where)
        super().__init__(config)

    def open_service(self) -> None:
        """Open the service now, before listening (else the app's lifespan opens it): a data folder in use or a
        Ray that does not answer is then an error before any port is taken, and nothing reports healthy first."""
        self.app.state.service = Service.open(self.settings)

    def bind(self) -> socket.socket:
        """Take the address now, before anything starts (uvicorn's own bind comes after the app's startup and
        fails with a log line and exit status 3): the socket to pass to ``run``. Raises OSError when the port is
        taken or the address is not this machine's."""
        family, kind, proto, _, address = socket.getaddrinfo(
            self.settings.host, self.settings.port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )[0]
        sock = socket.socket(family, kind, proto)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn: a restart need not wait TIME_WAIT
        try:
            sock.bind(address)
        except OSError:
            sock.close()
            raise
        sock.set_inheritable(True)
        return sock

    async def startup(self, sockets=None) -> None:
        await super().startup(sockets)
        if self.started and self.listening is not None:  # bound and listening: a connection is answered now
            self.listening()

    def handle_exit(self, sig, stack) -> None:  # stack: where the signal interrupted the program
        if self.should_exit and self._stop_paintings():
            return  # asked twice: no more waiting, but every caller still gets its answer
        super().handle_exit(sig, stack)

    async def shutdown(self, sockets=None) -> None:
        grace = asyncio.get_running_loop().call_later(self.settings.stop_grace_s, self._stop_paintings)
        try:
            await super().shutdown(sockets)
        finally:
            grace.cancel()

    def _stop_paintings(self) -> bool:
        """Stop the paintings, unless they are stopped already or the app has not started: True if it did."""
        service = service_of(self.app)
        if service is None or service.workshop.stopping:
            return False
        log.info("stopping the paintings in progress (%d)", service.workshop.in_progress)
        service.workshop.stop()
        return True
