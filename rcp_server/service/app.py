"""The app factory: settings in, scenes loaded at startup, one router per surface, the client at ``/``."""

from __future__ import annotations

import asyncio
import logging
import socket
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import uvicorn
from fastapi import FastAPI, Request, WebSocket
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.routing import Match, Mount
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from ..painting import paint
from ..params import PaintParams
from ..scene import Scene
from ..scenefile import SceneError, load_scene, scene_names
from . import protocol, rest
from .access import NEEDS_TOKEN, HideTokens, admits, origin_allowed
from .faults import InternalErrors
from .renderer import Renderer
from .session import Session
from .settings import Settings

log = logging.getLogger("rcp.service")


@dataclass
class Service:
    """What every request and session shares: settings, the scenes (and their descriptions, made once so a
    listing never builds geometry on the event loop), the renderer, the open sessions."""

    settings: Settings
    scenes: dict[str, Scene]
    infos: dict[str, protocol.SceneInfo]
    renderer: Renderer
    sessions: set = field(default_factory=set)


def scene_info(scene: Scene) -> protocol.SceneInfo:
    camera = scene.camera
    return protocol.SceneInfo(
        name=scene.name,
        title=scene.title,
        camera=protocol.CameraModel(eye=camera.eye, look_at=camera.look_at, up=camera.up, fov=camera.fov),
        paint=scene.paint.non_defaults(),
        animated=scene.animated,
        triangles=scene.geometry(0.0)[0].face_count,
    )


def load_scenes(settings: Settings) -> dict[str, Scene]:
    """Every scene of the scenes folder, ready to trace; a broken one is reported and skipped."""
    scenes = {}
    for name in scene_names(settings.scenes):
        try:
            scene = load_scene(name, settings.scenes)
            scene.geometry(0.0)  # build its BVH now, not on the first request
            scenes[name] = scene
        except SceneError as exc:
            log.error("scene %s skipped: %s", name, exc)
        except Exception:  # a fault the scene file's checks did not foresee: still only this scene's
            log.exception("scene %s skipped: it failed to build", name)
    return scenes


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        scenes = load_scenes(settings)
        for scene in list(scenes.values())[:1]:  # load the compiled kernels before a visitor waits for them
            paint(scene, scene.camera, 16, 16, PaintParams(iterations=2), threads=1)
        log.info("serving %d scenes: %s", len(scenes), ", ".join(scenes))
        infos = {name: scene_info(scene) for name, scene in scenes.items()}
        renderer = Renderer(settings.threads, settings.max_renders, settings.max_waiting)
        service = Service(settings, scenes, infos, renderer)
        app.state.service = service
        try:
            yield
        finally:
            for session in list(service.sessions):
                session.closed = True
            service.renderer.close()

    app = FastAPI(
        title="rcp",
        summary="Recursive Camera Painting: paint 3D scenes with per-pixel cameras.",
        lifespan=lifespan,
        max_body_size=settings.max_body_bytes,
    )
    app.add_middleware(InternalErrors)
    if settings.cors_origins:  # off unless configured: only the client served here calls the API
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST"],
            allow_headers=["Authorization", "Content-Type"],
        )
    app.add_exception_handler(RequestValidationError, _invalid)
    app.include_router(rest.public)
    app.include_router(rest.router)

    @app.websocket("/ws")
    async def walk_through(ws: WebSocket):
        service: Service = app.state.service
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

    if settings.client.is_dir():
        app.router.routes.append(_ClientFiles("/", StaticFiles(directory=settings.client, html=True), name="client"))
    return app


class _ClientFiles(Mount):
    """The client's static files at ``/``, except under ``/api/``: there a path the API lacks is a 404 and a
    method it lacks a 405 with ``Allow``, not a lookup among the client's files."""

    def matches(self, scope):
        if scope["type"] == "http" and scope["path"].startswith("/api/"):
            return Match.NONE, {}
        return super().matches(scope)


async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
    """FastAPI's 422, without echoing the input: a NaN or an infinity in it could not be written as JSON."""
    errors = [{"loc": list(e["loc"]), "msg": e["msg"], "type": e["type"]} for e in exc.errors()]
    return JSONResponse({"detail": errors}, 422)


def _refusal(ws: WebSocket, service: Service) -> tuple[int, str] | None:
    """Why a new walk-through may not start (a close code and a sentence), or None."""
    settings = service.settings
    if not origin_allowed(settings, ws.headers):
        return 1008, f"pages from {ws.headers['origin']} may not open walk-throughs here (see RCP_CORS_ORIGINS)"
    if not admits(settings, ws.headers, ws.query_params):
        return 1008, NEEDS_TOKEN
    if len(service.sessions) >= settings.max_sessions:
        return 1013, f"the server is at its limit of {settings.max_sessions} walk-throughs; try again later"
    return None


class _WebSockets(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol with the kernel's send buffer capped: the kernel would otherwise grow it to
    megabytes for a client that stops reading, holding seconds of stale frames before a send ever waits. With
    the cap, sends wait after ``SEND_BUFFER`` bytes and newer frames replace the unsent one (session.py)."""

    SEND_BUFFER = 256 * 1024

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.SEND_BUFFER)


class Server(uvicorn.Server):
    """uvicorn serving the app, with the transport's own limits: WebSocket messages (past this, the connection
    closes with 1009; the session's own, smaller limit answers with an error first), connections at once
    (past this, 503), and a stop that loses no answer.

    On SIGINT or SIGTERM, requests and walk-throughs in flight get ``PAINTING_GRACE_S`` to finish; then their
    paintings are stopped, so each caller is told "the server is stopping" (503) before uvicorn's own grace
    runs out and cancels whatever is left (a 500 and a traceback). A second signal stops the paintings at
    once; a third Ctrl-C is uvicorn's forced exit."""

    PAINTING_GRACE_S = 8
    GRACE_S = PAINTING_GRACE_S + 4  # uvicorn's: time for the stopped paintings to answer

    def __init__(self, settings: Settings, **options):
        config = uvicorn.Config(
            create_app(settings),
            host=settings.host,
            port=settings.port,
            ws=_WebSockets,
            ws_max_size=64 * settings.max_message_bytes,
            limit_concurrency=4 * (settings.max_sessions + settings.max_renders + settings.max_waiting) + 16,
            timeout_graceful_shutdown=self.GRACE_S,
            **options,
        )
        for name in ("uvicorn.error", "uvicorn.access"):
            logging.getLogger(name).addFilter(HideTokens())
        super().__init__(config)

    def handle_exit(self, sig, frame) -> None:
        if self.should_exit and self._stop_paintings():
            return  # asked twice: no more waiting, but every caller still gets its answer
        super().handle_exit(sig, frame)

    async def shutdown(self, sockets=None) -> None:
        grace = asyncio.get_running_loop().call_later(self.PAINTING_GRACE_S, self._stop_paintings)
        try:
            await super().shutdown(sockets)
        finally:
            grace.cancel()

    def _stop_paintings(self) -> bool:
        """Stop the paintings, unless they are stopped already or the app has not started: True if it did."""
        service = getattr(self.config.app.state, "service", None)
        if service is None or service.renderer.stopping:
            return False
        log.info("stopping the paintings in progress (%d)", service.renderer.painting)
        service.renderer.stop()
        return True
