"""The app factory, wiring only: settings in, the service opened by the lifespan, the middleware, one router
per surface (the token, where it is needed, given once, here), the client's files at ``/``."""

from __future__ import annotations

from contextlib import asynccontextmanager

from fastapi import Depends, FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match, Mount

from .access import NO_TOKEN, HostCheck, require_token
from .faults import InternalErrors
from .guard import BodyLimit, Capacity
from .refusal import Refusal
from .routes import docs, prints, rest, scenes, styles, videos, walk
from .settings import Settings
from .startup import Starting, Startup
from .state import Service, service_of


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        service = service_of(app) or Service.open(settings)  # opened already by `rcp serve`, or now
        app.state.service = service  # read back through state.get_service
        service.start()  # the scenes and the kernels, in a thread: the server answers meanwhile (startup.py)
        try:
            yield
        finally:
            service.close()

    app = FastAPI(
        title="rcp",
        summary="Recursive Camera Painting: paint 3D scenes with per-pixel cameras.",
        lifespan=lifespan,
        openapi_url=None,  # the schema and its pages are routes.docs, behind the token like the rest
        docs_url=None,
        redoc_url=None,
    )
    # every body's limit, uploads' their own (larger) one: a JSON 413 naming it
    uploads = (settings.upload_max_bytes, "the file", "RCP_UPLOAD_MAX_BYTES")
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes, larger={"/api/scenes": uploads})
    app.add_middleware(InternalErrors)  # outside the body limit: a 413 is an answer, not a fault
    app.add_middleware(Capacity, limit=settings.max_requests)  # inside CORS: a 503 keeps its CORS headers
    app.add_middleware(Starting, startup_of=lambda: startup_of(app))  # until ready, /api/ answers 503 starting
    if settings.cors_origins:  # off unless configured: only the client served here calls the API
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "DELETE"],
            allow_headers=["Authorization", "Content-Type"],
        )
    app.add_middleware(HostCheck, settings=settings)  # outermost: a name the server is not served under, nothing
    app.add_exception_handler(Refusal, _refused)  # every door's no, answered here once
    app.add_exception_handler(RequestValidationError, _invalid)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.include_router(rest.public)  # /api/health: open to all
    for router in (rest.router, scenes.router, styles.router, videos.router, videos.paths, prints.router, docs.router):
        app.include_router(router, dependencies=[Depends(require_token)], responses=NO_TOKEN)
    app.include_router(walk.router)  # the walk-through checks the token as it opens (walk.py)
    if settings.client.is_dir():
        app.router.routes.append(_ClientFiles("/", StaticFiles(directory=settings.client, html=True), name="client"))
    return app


def startup_of(app: FastAPI) -> Startup | None:
    service = service_of(app)
    return None if service is None else service.startup


class _ClientFiles(Mount):
    """The client's static files at ``/``, except under ``/api/``: there a path the API lacks is a 404 and a
    method it lacks a 405 with ``Allow``, not a lookup among the client's files."""

    def matches(self, scope):
        if scope["type"] == "http" and scope["path"].startswith("/api/"):
            return Match.NONE, {}
        return super().matches(scope)


async def _http_error(request: Request, exc: Exception) -> Response:
    """FastAPI's answer, except that a 405's ``Allow`` names the methods of every route at the path, not only
    those of the first (``GET`` and ``DELETE /api/videos/{id}`` are two routes): the one place it is set."""
    assert isinstance(exc, StarletteHTTPException)  # the handler of that class (Starlette types handlers loosely)
    if exc.status_code == 405:
        allowed = [
            method
            for method in ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")
            if any(route.matches({**request.scope, "method": method})[0] == Match.FULL for route in app_routes(request))
        ]
        exc.headers = {**(exc.headers or {}), "Allow": ", ".join(allowed)}
    return await http_exception_handler(request, exc)


def app_routes(request: Request) -> list:
    """The API's routes (the client's files, which take every path outside /api/, left out)."""
    return [route for route in request.app.routes if not isinstance(route, _ClientFiles)]


async def _refused(request: Request, exc: Exception) -> Response:
    """A :class:`~.refusal.Refusal`: its status, its line as ``detail`` (FastAPI's shape), its ``Retry-After``."""
    assert isinstance(exc, Refusal)  # the handler of that class
    return JSONResponse({"detail": exc.message}, exc.status, headers=exc.headers())


async def _invalid(request: Request, exc: Exception) -> Response:
    """FastAPI's 422, without echoing the input: a NaN or an infinity in it could not be written as JSON."""
    assert isinstance(exc, RequestValidationError)  # the handler of that class
    errors = [{"loc": list(e["loc"]), "msg": e["msg"], "type": e["type"]} for e in exc.errors()]
    return JSONResponse({"detail": errors}, 422)
