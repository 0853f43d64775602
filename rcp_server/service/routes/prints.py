"""REST: print jobs (``/api/prints``): a still at print size painted in the background into a PNG."""

from __future__ import annotations

import os

from fastapi import APIRouter, HTTPException, Response
from fastapi.responses import FileResponse

from ...camera.wire import camera_of
from .. import protocol
from ..asked import find_scene
from ..prints import PrintJob, Prints
from ..refusal import Refusal
from ..state import ServiceDep
from ..store import open_regular
from . import SCENE_BODY, Responses

router = APIRouter(prefix="/api/prints", tags=["prints"])
UNKNOWN: Responses = {404: {"description": "no such print (never made, deleted, or expired)"}}


def _status(job: PrintJob) -> protocol.PrintStatus:
    return protocol.PrintStatus(id=job.id, state=job.state, rows=job.height, done_rows=job.done_rows,
                                message=job.message)  # fmt: skip


def _prints(service) -> Prints:
    assert service.prints is not None  # opened with the service
    return service.prints


def _job(service, print_id: str) -> PrintJob:
    job = _prints(service).get(print_id)
    if job is None:
        raise HTTPException(404, f"no print {print_id!r}: never made, deleted, or expired")
    return job


@router.post(
    "",
    status_code=202,
    responses={
        **SCENE_BODY,
        422: {"description": "a setting the painting cannot take, or a print over the work limit"},
        503: {"description": "the print queue is full; see Retry-After"},
        507: {"description": "the print may not fit in the disk left to videos and prints (RCP_VIDEO_DISK_BYTES)"},
    },
)
async def create(body: protocol.PrintRequest, service: ServiceDep) -> protocol.PrintStatus:
    """Queue a print; watch it at ``GET /api/prints/{id}`` (rows painted), fetch it from ``.../file``."""
    scene = find_scene(service, body.scene)
    try:
        camera = scene.camera if body.camera is None else camera_of(body.camera)
        params = scene.painting(body.paint.given())
        width, height = camera.image_size(body.width, body.height)
        job = _prints(service).submit(scene, camera, width, height, params, body.time, body.bits, body.alpha)
    except ValueError as exc:  # CameraError among them; the queue's and the disk's answers are Refusals
        raise Refusal(str(exc)) from None
    return _status(job)


@router.get("/{print_id}", responses=UNKNOWN)
async def status(print_id: str, service: ServiceDep) -> protocol.PrintStatus:
    """How far the print is, in rows."""
    return _status(_job(service, print_id))


@router.delete("/{print_id}", responses=UNKNOWN)
async def delete(print_id: str, service: ServiceDep) -> protocol.PrintStatus:
    """Cancel a print in progress (it stops within a tile); a finished one is forgotten and its file deleted."""
    job = _prints(service).delete(print_id)
    if job is None:
        raise HTTPException(404, f"no print {print_id!r}: never made, deleted, or expired")
    return _status(job)


@router.get(
    "/{print_id}/file",
    response_class=FileResponse,
    responses={
        200: {"content": {"image/png": {}}, "description": "the print"},
        409: {"description": "the print is not done (yet, or ever)"},
        **UNKNOWN,
    },
)
async def file(print_id: str, service: ServiceDep) -> Response:
    job = _job(service, print_id)
    if job.state != "done":
        raise HTTPException(409, f"print {print_id} is {job.state}, not done: {job.message or 'wait for it'}")
    try:
        with open_regular(job.file, service.settings.video_disk_bytes) as source:
            info = os.fstat(source.fileno())
    except OSError:
        raise HTTPException(409, f"print {print_id} is done but its file is lost; ask for it again") from None
    return FileResponse(job.file, media_type="image/png", filename=f"{job.scene.name}-{job.id}.png", stat_result=info)
