"""REST: health, the scene list, and renders of a single painting (``POST /api/render``)."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request, Response

from .. import images
from ..camera import Camera, CameraError
from ..painting import PaintParams
from . import protocol

router = APIRouter(prefix="/api")

MEDIA_TYPES = {"png": ("PNG", "image/png"), "jpeg": ("JPEG", "image/jpeg")}


@router.get("/health")
def health(request: Request) -> dict:
    service = request.app.state.service
    return {
        "status": "ok",
        "scenes": len(service.scenes),
        "sessions": len(service.sessions),
        "threads": service.renderer.threads,
    }


@router.get("/scenes")
def scenes(request: Request) -> list[protocol.SceneInfo]:
    return list(request.app.state.service.infos.values())


@router.post(
    "/render",
    response_class=Response,
    responses={
        200: {"content": {"image/png": {}, "image/jpeg": {}}, "description": "the painting"},
        404: {"description": "no such scene"},
        422: {"description": "a request the painting cannot take"},
    },
)
async def render(body: protocol.RenderRequest, request: Request) -> Response:
    service = request.app.state.service
    scene = service.scenes.get(body.scene)
    if scene is None:
        raise HTTPException(404, f"unknown scene {body.scene!r}; known: {', '.join(sorted(service.scenes))}")
    limit = service.settings.max_pixels
    if body.width * body.height > limit:
        raise HTTPException(422, f"{body.width}x{body.height} is more than the {limit} pixels an image may have")
    try:
        camera = scene.camera if body.camera is None else Camera(**body.camera.model_dump())
        params = PaintParams.from_dict({**scene.paint, **body.paint.given()})
    except (CameraError, ValueError) as exc:
        raise HTTPException(422, str(exc)) from None
    fmt, media_type = MEDIA_TYPES[body.format]
    renderer = service.renderer

    def job() -> bytes:
        result = renderer.paint(scene, camera, body.width, body.height, params, time=body.time)
        return images.encode(result.image, fmt, body.quality)

    return Response(await renderer.run(job), media_type=media_type)
