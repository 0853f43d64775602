"""Who may call: the optional token (REST and WebSocket), the origins a browser may call from, and a log
that never shows the token.

A token travels as ``Authorization: Bearer <token>`` or, for browsers (whose WebSocket API cannot set
headers), as ``?token=<token>`` in the address.
"""

from __future__ import annotations

import logging
import re
import secrets
from typing import Annotated
from urllib.parse import urlsplit

from fastapi import HTTPException, Request, Security
from fastapi.security import APIKeyQuery, HTTPAuthorizationCredentials, HTTPBearer
from starlette.datastructures import Headers, QueryParams

from .settings import Settings
from .state import ServiceDep

# documented in the OpenAPI schema as the two ways to present the token
BEARER = HTTPBearer(auto_error=False, description="the token of RCP_TOKEN, when the server has one")
QUERY = APIKeyQuery(name="token", auto_error=False, description="the same token, for browsers' WebSockets")

NEEDS_TOKEN = "this server needs a token: send 'Authorization: Bearer <token>' or add ?token=<token> to the address"


def presented(headers: Headers, query: QueryParams) -> str | None:
    scheme, _, credentials = headers.get("authorization", "").partition(" ")
    return credentials.strip() if scheme.lower() == "bearer" else query.get("token")


def admits(settings: Settings, headers: Headers, query: QueryParams) -> bool:
    """The one check of REST and WebSocket callers alike: no token set, or the token presented."""
    if settings.token is None:
        return True
    given = presented(headers, query)
    return given is not None and secrets.compare_digest(given.encode(), settings.token.get_secret_value().encode())


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


class HideTokens(logging.Filter):
    """Blanks ``token=...`` in log lines (uvicorn logs every address, query included)."""

    _TOKEN = re.compile(r"(token=)[^&\s\"']+")

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.args, tuple):
            record.args = tuple(self._TOKEN.sub(r"\1***", a) if isinstance(a, str) else a for a in record.args)
        record.msg = self._TOKEN.sub(r"\1***", str(record.msg))
        return True
