"""Scenes over REST: the operator's listed (``GET /api/scenes``); visitors' own uploaded (``POST /api/scenes``);
any described by name, an uploaded one deleted.

Uploads have their own body limit (``RCP_UPLOAD_MAX_BYTES``, app.py), larger than the JSON routes'
``RCP_MAX_BODY_BYTES``.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response, UploadFile
from starlette.concurrency import run_in_threadpool

from ...scene.scenefile import SCENE_NAME
from .. import protocol
from ..access import presented
from ..asked import read_upload, upload_door
from ..refusal import Refusal
from ..state import Service, ServiceDep, scene_info

router = APIRouter(prefix="/api")
NamePath = Annotated[str, Path(pattern=f"^{SCENE_NAME.pattern}$")]


@router.get("/scenes")
async def scenes(service: ServiceDep) -> list[protocol.SceneInfo]:
    """The operator's scenes (uploaded ones are not listed: their names are their holders' secret)."""
    return list(service.infos.values())


@router.post(
    "/scenes",
    status_code=201,
    responses={
        400: {"description": "a body that is not multipart form data"},
        403: {"description": "uploads are off on this server (RCP_UPLOADS=0)"},
        413: {"description": "the file is larger than RCP_UPLOAD_MAX_BYTES"},
        422: {"description": "a file that is not a model this server reads, or one over a limit; the detail says"},
        503: {"description": "the uploaded scenes fill their count or memory, or other uploads are being read"},
    },
    form_limits={"max_files": 1, "max_fields": 16},  # fields beside `file` are ignored; a flood of them is a 400
)
async def upload(file: UploadFile, request: Request, response: Response, service: ServiceDep) -> protocol.SceneInfo:
    """A model as a new scene: a `.glb`; a `.gltf` with its files in a `.zip`; an `.obj` alone or in a `.zip`
    with its `.mtl` and textures; a `.ply` or an `.stl`. The answer describes it as `GET /api/scenes` does
    (`uploaded` true), under a new name that only the uploader knows; use it wherever a scene name goes."""
    settings, uploads = service.settings, service.uploads
    upload_door(service)
    uploads.queued += 1
    try:
        async with uploads.reading:
            limits = settings.upload_limits(room_bytes=settings.upload_total_bytes - uploads.weight)
            scene, weight = await run_in_threadpool(
                read_upload, file.file, file.filename or "", limits, service.store.uploads_dir
            )
    finally:
        uploads.queued -= 1
    # its description is built off the event loop too: a model's cameras make it (bounded, gltf.MAX_VIEWPOINTS)
    info = (await run_in_threadpool(scene_info, scene)).model_copy(update={"uploaded": True})
    owner = presented(request.headers, request.query_params) if settings.token is not None else None
    try:
        uploads.add(scene, info, weight, settings.upload_max_scenes, settings.upload_total_bytes, owner)
    except Refusal:
        service.store.remove_upload(scene.name)  # its files, kept by read_scene
        raise
    response.headers["Location"] = f"/api/scenes/{scene.name}"
    return info


@router.get("/scenes/{name}", responses={404: {"description": "no such scene (an uploaded one may have expired)"}})
async def describe(name: NamePath, service: ServiceDep) -> protocol.SceneInfo:
    """One scene's description, the operator's or an uploaded one."""
    info = service.info(name)
    if info is None:
        raise Refusal(_unknown(name, service), 404)
    return info


@router.delete(
    "/scenes/{name}",
    status_code=204,
    responses={403: {"description": "an operator's scene, which cannot be deleted"}, 404: {"description": "no such"}},
)
async def delete(name: NamePath, service: ServiceDep) -> Response:
    """Removes an uploaded scene (walk-throughs showing it keep it until they leave it)."""
    if name in service.scenes:
        raise Refusal(f"{name!r} is one of the server's own scenes; only uploaded scenes can be deleted", 403)
    if service.uploaded(name) is None or not service.uploads.remove(name):
        raise Refusal(_unknown(name, service), 404)
    return Response(status_code=204)


def _unknown(name: str, service: Service) -> str:
    minutes = service.settings.upload_idle_s / 60
    return f"unknown scene {name!r} (uploaded scenes are removed after {minutes:g} minutes unused)"
