"""REST: video jobs (``/api/videos``): a camera path painted into an MP4 in the background."""

from __future__ import annotations

import os

from fastapi import APIRouter, Response
from fastapi.responses import FileResponse
from starlette.concurrency import run_in_threadpool

from ...camera.wire import spec_of
from .. import protocol
from ..asked import SceneDep, VideoAskedDep, keyed_paint, resolved
from ..refusal import Refusal
from ..state import ServiceDep
from ..store import open_regular
from ..videos import VideoJob
from . import SCENE_BODY, Responses

router = APIRouter(prefix="/api/videos", tags=["videos"])
UNKNOWN: Responses = {404: {"description": "no such video (never made, deleted, or expired)"}}


def _status(job: VideoJob) -> protocol.VideoStatus:
    return protocol.VideoStatus(
        id=job.id, state=job.state, frames=job.frames, done_frames=job.done_frames, message=job.message
    )


def _job(service, video_id: str) -> VideoJob:
    job = service.videos.get(video_id)
    if job is None:
        raise Refusal(f"no video {video_id!r}: never made, deleted, or expired", 404)
    return job


paths = APIRouter(prefix="/api/paths", tags=["videos"])
PREVIEW_FRAMES = 3600  # cameras one path preview answers with (a minute at 60 fps; longer paths are stepped)


@paths.post(
    "",
    responses={
        **SCENE_BODY,
        422: {"description": "a path the painting cannot take"},
    },
)
async def path_cameras(body: protocol.PathRequest, scene: SceneDep) -> protocol.PathCameras:
    """The cameras of a path's frames, as a video of it paints them (every ``step``-th frame of a long path),
    and the painting it keys on each over ``paint``; ``path`` may name one of the scene's animated cameras
    (``{"camera": name}``)."""
    path = await resolved(body.path, scene)  # a Refusal in one line
    step = -(-path.frame_count // PREVIEW_FRAMES)
    times = path.frame_times()[::step]
    cameras, scene_times = path.at(times)
    paints = await run_in_threadpool(keyed_paint, path, scene, body.paint.given(), times)
    return protocol.PathCameras(
        fps=path.fps / step,
        step=step,
        frames=path.frame_count,
        cameras=[spec_of(c) for c in cameras],
        scene_times=scene_times,
        paints=paints,
    )


@router.post(
    "",
    status_code=202,
    responses={
        **SCENE_BODY,
        422: {"description": "a path or setting the painting cannot take, or one over a limit"},
        503: {"description": "every place in the video queue is taken; see Retry-After"},
        507: {
            "description": "the video's estimated size does not fit in the disk left to videos (RCP_VIDEO_DISK_BYTES)"
        },
    },
)
async def create(body: protocol.VideoRequest, asked: VideoAskedDep, service: ServiceDep) -> protocol.VideoCreated:
    """Queue a video of ``path``; watch it at ``GET /api/videos/{id}``, fetch it from ``.../file``."""
    frame = asked.frame
    job = service.videos.submit(frame.scene, asked.path, body.width, body.height, frame.params, body.temporal)
    return protocol.VideoCreated(id=job.id, frames=job.frames)


@router.get("/{video_id}", responses=UNKNOWN)
async def status(video_id: str, service: ServiceDep) -> protocol.VideoStatus:
    """How far the video is."""
    return _status(_job(service, video_id))


@router.delete("/{video_id}", responses=UNKNOWN)
async def delete(video_id: str, service: ServiceDep) -> protocol.VideoStatus:
    """Cancel a video in progress (it stops within a tile); a finished one is forgotten and its file deleted."""
    job = service.videos.delete(video_id)
    if job is None:
        raise Refusal(f"no video {video_id!r}: never made, deleted, or expired", 404)
    return _status(job)


@router.get(
    "/{video_id}/file",
    response_class=FileResponse,
    responses={
        200: {"content": {"video/mp4": {}}, "description": "the video"},
        409: {"description": "the video is not done (yet, or ever)"},
        **UNKNOWN,
    },
)
async def file(video_id: str, service: ServiceDep) -> Response:
    job = _job(service, video_id)
    if job.state != "done":
        raise Refusal(f"video {video_id} is {job.state}, not done: {job.message or 'wait for it'}", 409)
    try:  # only a regular file of the data folder is served: never a link, wherever it points, nor a FIFO
        with open_regular(job.file, service.settings.video_disk_bytes) as source:
            info = os.fstat(source.fileno())
    except OSError:
        raise Refusal(f"video {video_id} is done but its file is lost; ask for it again", 409) from None
    return FileResponse(job.file, media_type="video/mp4", filename=f"{job.scene_name}-{job.id}.mp4", stat_result=info)
