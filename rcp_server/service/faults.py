"""Faults: whatever goes wrong inside is logged once, with its trace and a short id; the caller gets the id
and a sentence, never the trace."""

from __future__ import annotations

import logging
import uuid

from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

log = logging.getLogger("rcp.service")


def report_fault(what: str) -> str:
    """Log the exception being handled with a new id; returns the id for the caller's message."""
    error_id = uuid.uuid4().hex[:12]
    log.exception("error %s: %s", error_id, what)
    return error_id


def fault_message(error_id: str) -> str:
    return f"internal error {error_id}: the server log has the details under that id"


class InternalErrors:
    """ASGI middleware: an HTTP request that raises is answered 500 with an error id (unless its response has
    already begun) and the server goes on."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        started = False
        outer = False  # the exception came from the layers outside, through their send: theirs to handle

        async def watched(message: Message) -> None:
            nonlocal started, outer
            started = started or message["type"] == "http.response.start"
            try:
                await send(message)
            except BaseException:
                outer = True  # e.g. the body limit, telling its own layer it has answered 413 itself
                raise

        try:
            await self.app(scope, receive, watched)
        except Exception:
            if outer:
                raise
            error_id = report_fault(f"{scope['method']} {scope['path']}")
            if not started:
                await JSONResponse({"detail": fault_message(error_id)}, 500)(scope, receive, send)
