"""The API's description: its OpenAPI schema (``/openapi.json``) and the pages that show it (``/docs``,
``/redoc``). FastAPI's own routes for them are off (app.py): these are included like every other router,
behind the token when the server has one. A page opened with ``?token=`` fetches the schema with it."""

from __future__ import annotations

from urllib.parse import quote

from fastapi import APIRouter, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import HTMLResponse, JSONResponse

router = APIRouter(include_in_schema=False)
READ = ["GET", "HEAD"]
SCHEMA = "/openapi.json"
OAUTH2_REDIRECT = "/docs/oauth2-redirect"


@router.api_route(SCHEMA, methods=READ)
async def schema(request: Request) -> JSONResponse:
    return JSONResponse(request.app.openapi())


@router.api_route("/docs", methods=READ)
async def swagger(request: Request) -> HTMLResponse:
    title = f"{request.app.title} - Swagger UI"
    return get_swagger_ui_html(openapi_url=_schema_url(request), title=title, oauth2_redirect_url=OAUTH2_REDIRECT)


@router.api_route(OAUTH2_REDIRECT, methods=READ)
async def oauth2_redirect() -> HTMLResponse:
    return get_swagger_ui_oauth2_redirect_html()


@router.api_route("/redoc", methods=READ)
async def redoc(request: Request) -> HTMLResponse:
    return get_redoc_html(openapi_url=_schema_url(request), title=f"{request.app.title} - ReDoc")


def _schema_url(request: Request) -> str:
    """The schema's address for a page's script: with the page's own ``?token=`` (quoted: only characters that
    are safe in a URL, and so in the page's script) when it was opened with one."""
    token = request.query_params.get("token")
    return SCHEMA if token is None else f"{SCHEMA}?token={quote(token, safe='')}"
