"""The app factory, wiring only: settings in, the service opened by the lifespan, the middleware, one router
per surface, the client's files at ``/``."""

from __future__ import annotations

from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.routing import Match, Mount

from .faults import InternalErrors
from .routes import rest, videos, walk
from .settings import Settings
from .state import Service


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        service = Service.open(settings)
        app.state.service = service  # read back through state.get_service
        try:
            yield
        finally:
            service.close()

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
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["Authorization", "Content-Type"],
        )
    app.add_exception_handler(RequestValidationError, _invalid)
    app.include_router(rest.public)
    app.include_router(rest.router)
    app.include_router(videos.router)
    app.include_router(videos.paths)
    app.include_router(walk.router)
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
