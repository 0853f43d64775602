"""REST: health (open to all) and renders of a single painting (``POST /api/render``)."""

from __future__ import annotations

import asyncio
import logging
import threading
import time

from fastapi import APIRouter, Request, Response

from ...painting.loop import Abandoned
from ...util import images
from .. import protocol
from ..access import admits
from ..asked import RenderAsked
from ..memory import painting_bytes
from ..refusal import Refusal
from ..state import ServiceDep
from . import SCENE_BODY

public = APIRouter(prefix="/api")  # the one route without the token (app.py puts it on the others)
router = APIRouter(prefix="/api")

MEDIA_TYPES = {"png": ("PNG", "image/png"), "jpeg": ("JPEG", "image/jpeg")}
BUSY = {"description": "every render place is taken, the render ran out of time, or Ray failed; see Retry-After"}
log = logging.getLogger("rcp.service")


STARTING = {
    "description": "the server is starting (the scenes load, the kernels compile): the body says how far, in "
    "`phase`, `done` of `total` kernels and `detail`; see Retry-After. Every /api/ path answers so meanwhile."
}


@public.get("/health", responses={503: STARTING})
async def health(request: Request, service: ServiceDep) -> dict:
    """Open to all (for container health checks); the figures only for callers with the token. While the server
    starts, a 503 "starting" (service/startup.py answers it)."""
    if not admits(service.settings, request.headers, request.query_params):
        return {"status": "ok"}
    return {
        "status": "ok",
        "scenes": len(service.scenes),
        "sessions": len(service.sessions),
        "threads": service.workshop.threads,
        "renders": service.workshop.admitted,
        "painting": service.workshop.in_progress,
        **service.painter.figures(),
    }


@router.post(
    "/render",
    response_class=Response,
    responses={
        200: {"content": {"image/png": {}, "image/jpeg": {}}, "description": "the painting"},
        **SCENE_BODY,
        422: {"description": "a request the painting cannot take, or one over a limit"},
        503: BUSY,
    },
)
async def render(body: protocol.RenderRequest, asked: RenderAsked, request: Request, service: ServiceDep) -> Response:
    settings = service.settings
    scene, camera, params, size = asked.scene, asked.camera, asked.params, (asked.width, asked.height)
    fmt, media_type = MEDIA_TYPES[body.format]
    workshop = service.workshop
    deadline = time.monotonic() + settings.render_timeout_s  # waiting for a turn counts too
    gone = threading.Event()  # the caller hung up: paint no further

    def stop() -> bool:
        return gone.is_set() or time.monotonic() > deadline or workshop.stopping

    def job() -> bytes:
        return images.encode(service.painter.render(scene, camera, *size, params, body.time, stop), fmt, body.quality)

    try:
        with workshop.admission(), service.memory.reserved(painting_bytes(params, *size), size, "this render"):
            watcher = asyncio.create_task(_hang_up(request, gone))
            try:
                return Response(await workshop.run(job), media_type=media_type)
            finally:
                watcher.cancel()
    except Abandoned:
        if gone.is_set():
            log.info("a render stopped at its next tile: its caller left")
            return Response(status_code=499)  # nobody is left to tell (nginx's "client closed request")
        if workshop.stopping:
            message = "the server is stopping"
        else:
            message = f"the render ran past the server's {settings.render_timeout_s:g} s limit; ask for less, or later"
        raise Refusal(message, 503, 10) from None


async def _hang_up(request: Request, gone: threading.Event) -> None:
    """Set ``gone`` when the caller disconnects (the body is read; the next message is the disconnect)."""
    while (await request.receive())["type"] != "http.disconnect":
        await asyncio.sleep(0.05)
    gone.set()
