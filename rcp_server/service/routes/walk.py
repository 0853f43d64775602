"""The walk-through's route (``/ws``): who may open one, then a :class:`~rcp_server.service.session.Session`."""

from __future__ import annotations

from fastapi import APIRouter, WebSocket

from .. import protocol
from ..access import NEEDS_TOKEN, admits, origin_allowed
from ..session import Session, busy_message
from ..state import Service, ServiceDep

router = APIRouter()


@router.websocket("/ws")
async def walk_through(ws: WebSocket, service: ServiceDep):
    await ws.accept()
    refusal = _refusal(ws, service)
    if refusal is not None:
        code, message = refusal
        await ws.send_text(protocol.Error(message=message).model_dump_json())
        await ws.close(code=code, reason=message[:120])
        return
    session = Session(ws, service)
    service.sessions.add(session)
    try:
        await session.run()
    finally:
        service.sessions.discard(session)


def _refusal(ws: WebSocket, service: Service) -> tuple[int, str] | None:
    """Why a new walk-through may not start (a close code and a sentence), or None."""
    settings = service.settings
    if not service.startup.ready:  # the scenes load and the kernels compile (startup.py): the client tries again
        return 1013, service.startup.message()
    if not origin_allowed(settings, ws.headers):
        return 1008, f"pages from {ws.headers['origin']} may not open walk-throughs here (see RCP_CORS_ORIGINS)"
    if not admits(settings, ws.headers, ws.query_params):
        return 1008, NEEDS_TOKEN
    if service.walking() >= settings.max_sessions:
        return 1013, busy_message(settings.max_sessions, settings.walk_retry_s)
    return None
