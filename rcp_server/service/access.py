"""Who may call: the names the server answers to (``Host``), the optional token (REST and WebSocket), the
origins a browser may call from, and a log that never shows the token.

A token travels as ``Authorization: Bearer <token>`` or, for browsers (whose WebSocket API cannot set
headers), as ``?token=<token>`` in the address.

``Host`` is checked as Jupyter Server checks it: a server on a loopback address answers only to loopback
names (``localhost``, ``127.0.0.1``, ``[::1]``) and those of ``RCP_ALLOWED_HOSTS``, so that a web page whose
own name an attacker rebinds to 127.0.0.1 (DNS rebinding) cannot drive it from the visitor's browser; a
server bound to another address answers to any name unless ``RCP_ALLOWED_HOSTS`` says which.
"""

from __future__ import annotations

import ipaddress
import logging
import re
import secrets
from typing import Annotated, Any
from urllib.parse import urlsplit

from fastapi import HTTPException, Request, Security
from fastapi.security import APIKeyQuery, HTTPAuthorizationCredentials, HTTPBearer
from starlette.datastructures import Headers, QueryParams
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from .settings import Settings
from .state import ServiceDep

# documented in the OpenAPI schema as the two ways to present the token
BEARER = HTTPBearer(auto_error=False, description="the token of RCP_TOKEN, when the server has one")
QUERY = APIKeyQuery(name="token", auto_error=False, description="the same token, for browsers' WebSockets")

NEEDS_TOKEN = "this server needs a token: send 'Authorization: Bearer <token>' or add ?token=<token> to the address"
NO_TOKEN: dict[int | str, dict[str, Any]] = {
    401: {"description": "the server has a token (RCP_TOKEN) and the request did not bring it"}
}
"""The answer :func:`require_token` adds to a route's, declared where the routers are included (app.py)."""


def presented(headers: Headers, query: QueryParams) -> str | None:
    scheme, _, credentials = headers.get("authorization", "").partition(" ")
    return credentials.strip() if scheme.lower() == "bearer" else query.get("token")


def admits(settings: Settings, headers: Headers, query: QueryParams) -> bool:
    """The one check of REST and WebSocket callers alike: no token set, or the token presented."""
    if settings.token is None:
        return True
    given = presented(headers, query)
    if not given or not settings.token.get_secret_value():  # an empty token is no token, given or set
        return False
    return secrets.compare_digest(given.encode(), settings.token.get_secret_value().encode())


async def require_token(
    request: Request,
    service: ServiceDep,
    _bearer: Annotated[HTTPAuthorizationCredentials | None, Security(BEARER)],  # for the OpenAPI schema
    _token: Annotated[str | None, Security(QUERY)],
) -> None:
    """The REST routes' dependency: 401 unless the token (if the server has one) came with the request. Async,
    like the light routes, so that none of them takes a worker thread."""
    if not admits(service.settings, request.headers, request.query_params):
        raise HTTPException(401, NEEDS_TOKEN, headers={"WWW-Authenticate": "Bearer"})


def origin_allowed(settings: Settings, headers: Headers) -> bool:
    """A WebSocket's browser origin: its own page, or one of ``cors_origins``. Browsers apply no CORS to
    WebSockets, so without this any page a visitor opens could walk through the server in their name."""
    origin = headers.get("origin")
    if origin is None:  # not a browser
        return True
    allowed = settings.cors_origins
    return origin in allowed or "*" in allowed or urlsplit(origin).netloc == headers.get("host")


def host_allowed(settings: Settings, host: str) -> bool:
    """Whether a request's ``Host`` (``name`` or ``name:port``) is a name this server answers to."""
    name = _name_of(host)
    allowed = settings.allowed_hosts
    if "*" in allowed or name in (_name_of(h) for h in allowed):
        return True
    if not allowed and not _loopback(settings.host):
        return True  # bound to another address: any name, unless RCP_ALLOWED_HOSTS says which
    return name == "localhost" or name.endswith(".localhost") or _loopback(name)


def _name_of(host: str) -> str:
    """The name of a ``Host`` header, without its port or an IPv6 address's brackets, lower case."""
    host = host.strip().lower()
    if host.startswith("["):  # [::1]:8000
        host = host[1 : host.find("]")] if "]" in host else host
    elif host.count(":") == 1:  # name:port (a bare IPv6 address has more colons)
        host = host.split(":")[0]
    return host.rstrip(".")


def _loopback(address: str) -> bool:
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return address == "localhost"


class HostCheck:
    """ASGI middleware: a request or WebSocket whose ``Host`` is not one of the server's names is refused (HTTP:
    403 with a JSON ``detail``; WebSocket: its handshake is refused, 403) before anything else sees it."""

    def __init__(self, app: ASGIApp, settings: Settings):
        self.app, self.settings = app, settings

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        host = Headers(scope=scope).get("host", "")
        if host_allowed(self.settings, host):
            return await self.app(scope, receive, send)
        detail = f"this server does not answer to the name {host[:80]!r} (see RCP_ALLOWED_HOSTS)"
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008, "reason": detail[:120]})
            return
        await JSONResponse({"detail": detail}, 403)(scope, receive, send)


class HideTokens(logging.Filter):
    """Blanks ``token=...`` in log lines (uvicorn logs every address, query included)."""

    _TOKEN = re.compile(r"(token=)[^&\s\"']+")

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(self._TOKEN.sub(r"\1***", a) if isinstance(a, str) else a for a in record.args)
        record.msg = self._TOKEN.sub(r"\1***", str(record.msg))
        return True
