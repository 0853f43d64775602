"""The app factory: settings in, scenes loaded at startup, one router per surface, the client at ``/``."""

from __future__ import annotations

import logging
from contextlib import asynccontextmanager

from fastapi import FastAPI, WebSocket
from fastapi.staticfiles import StaticFiles

from ..painting import PaintParams, paint
from ..scene import Scene
from ..scenefile import SceneError, load_scene, scene_names
from . import protocol, rest
from .renderer import Renderer
from .session import Session
from .settings import Settings

log = logging.getLogger("rcp.service")


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
    return scenes


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        app.state.scenes = load_scenes(settings)
        for scene in list(app.state.scenes.values())[:1]:  # load the compiled kernels before a visitor waits
            paint(scene, scene.camera, 16, 16, PaintParams(iterations=2), threads=1)
        log.info("serving %d scenes: %s", len(app.state.scenes), ", ".join(app.state.scenes))
        app.state.renderer = Renderer(settings.threads, settings.max_renders)
        try:
            yield
        finally:
            for session in list(app.state.sessions):
                session.closed = True
            app.state.renderer.close()

    app = FastAPI(
        title="rcp", summary="Recursive Camera Painting: paint 3D scenes with per-pixel cameras.", lifespan=lifespan
    )
    app.state.settings = settings
    app.state.sessions = set()
    app.include_router(rest.router)

    @app.websocket("/ws")
    async def walk_through(ws: WebSocket):
        await ws.accept()
        if len(app.state.sessions) >= settings.max_sessions:
            message = f"the server is at its limit of {settings.max_sessions} walk-throughs; try again later"
            await ws.send_text(protocol.Error(message=message).model_dump_json())
            await ws.close(code=1013, reason="too many sessions")
            return
        session = Session(ws, app.state.scenes, app.state.renderer, settings)
        app.state.sessions.add(session)
        try:
            await session.run()
        finally:
            app.state.sessions.discard(session)

    if settings.client.is_dir():
        app.mount("/", StaticFiles(directory=settings.client, html=True), name="client")
    return app
