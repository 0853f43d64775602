"""What a request asks to have painted, decided in one place for every door: the scene its name stands for, the
painting settings built from the scene's and the caller's, and their cost checked against the limits
(:meth:`~.settings.Settings.painting_size`: both eyes of a stereo pair, every sample, every iteration).

REST renders and video jobs take it as a FastAPI dependency (``asked: RenderAsked``, ``asked: VideoAsked``, as
FastAPI's "bigger applications" declare theirs); the walk-through calls :func:`asked` for its ``hello`` and
:func:`check` for every later message that changes the camera, the size or the settings. So one request is
refused alike, in the same line, whichever door it comes through.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, BinaryIO

import numpy as np
from fastapi import Depends
from starlette.concurrency import run_in_threadpool

from ..camera.camera import Camera
from ..camera.wire import camera_of
from ..media.camerapath import CAMERA_PREFIX, CameraPath, PathError, PathSpec, motion_path
from ..scene.scene import Scene
from ..settings.params import PaintParams
from . import protocol
from .refusal import Refusal
from .settings import Settings
from .state import Service, ServiceDep
from .uploads import Limits, Refused, read_refusal, read_scene
from .videos import job_work


@dataclass(frozen=True)
class Asked:
    """A painting that a door let through: its scene, camera and settings, and its size in pixels (both eyes
    of a stereo pair: ``width x height`` as painted, not the eye's image the caller gave)."""

    scene: Scene
    camera: Camera
    params: PaintParams
    width: int
    height: int


def find_scene(service: Service, name: str) -> Scene:
    """The scene ``name`` stands for (the operator's or an uploaded one), or :class:`Refusal` 404."""
    scene = service.scene(name)
    if scene is None:
        raise Refusal(service.unknown_scene(name), 404)
    return scene


def check(
    settings: Settings, scene: Scene, camera: Camera | None, width: int, height: int, overrides: dict[str, Any]
) -> Asked:
    """The painting of ``scene`` by ``camera`` (None: the scene's) of an eye's image of ``width x height`` with
    the caller's ``overrides`` of the scene's settings, or :class:`Refusal` (a setting the scene cannot take, a
    size the projection does not take, more pixels or work than one painting may take)."""
    camera = scene.camera if camera is None else camera
    try:
        params = scene.painting(overrides)
        size = settings.painting_size(camera, width, height, params)
    except ValueError as exc:  # CameraError among them
        raise Refusal(str(exc)) from None
    return Asked(scene, camera, params, *size)


def asked(
    service: Service,
    name: str,
    camera: protocol.CameraModel | None,
    width: int,
    height: int,
    overrides: dict[str, Any],
) -> Asked:
    """:func:`check` of the scene ``name`` stands for, with the camera as the wire gives it."""
    scene = find_scene(service, name)
    try:
        chosen = None if camera is None else camera_of(camera)
    except ValueError as exc:
        raise Refusal(str(exc)) from None
    return check(service.settings, scene, chosen, width, height, overrides)


# ---- the dependencies of the REST routes ----


async def render_asked(body: protocol.RenderRequest, service: ServiceDep) -> Asked:
    """``POST /api/render``'s painting (the route reads the same ``body``: FastAPI parses it once)."""
    return asked(service, body.scene, body.camera, body.width, body.height, body.paint.given())


@dataclass(frozen=True)
class VideoAsked:
    """A video's painting as its door checked it: every frame's (a path holds one projection and one stereo
    layout, so its first camera stands for all), and the path resolved."""

    frame: Asked
    path: CameraPath


async def video_asked(body: protocol.VideoRequest, service: ServiceDep) -> VideoAsked:
    """``POST /api/videos``' path and painting; the whole film's work is the video queue's to check."""
    scene = find_scene(service, body.scene)
    path = await resolved(body.path, scene)
    frame = check(service.settings, scene, path.cameras[0], body.width, body.height, body.paint.given())
    return VideoAsked(frame, keyed(service, path, frame, body.temporal))


async def resolved(spec: PathSpec | protocol.CameraPathRef, scene: Scene) -> CameraPath:
    """A request's path: keyframes resolved against the scene's camera, or one of the scene's animated cameras
    (looking as far ahead as the scene's camera does); every frame checked, off the event loop (up to a
    second). :class:`Refusal` in one line."""
    try:
        if isinstance(spec, protocol.CameraPathRef):
            distance = float(np.linalg.norm(np.subtract(scene.camera.look_at, scene.camera.eye)))
            ref = CAMERA_PREFIX + spec.camera
            return await run_in_threadpool(motion_path, ref, scene.motions, spec.fps, distance)
        return await run_in_threadpool(spec.resolve, scene.camera)
    except PathError as exc:
        raise Refusal(str(exc)) from None


def keyed_paint(path: CameraPath, scene: Scene, overrides: dict[str, Any], times: np.ndarray) -> list[dict[str, Any]]:
    """Blocking: what ``path`` keys at seconds ``times (m,)`` over the film's painting (the scene's with the
    caller's ``overrides``), one ``paint`` table a time (:meth:`.CameraPath.keyed_paint`; ``[]``: it keys none),
    or :class:`Refusal` in one line for a painting the scene cannot take."""
    try:
        return path.with_painting(scene.painting(overrides), scene.check_names).keyed_paint(times)
    except ValueError as exc:  # PathError among them
        raise Refusal(str(exc)) from None


def keyed(service: Service, path: CameraPath, frame: Asked, temporal: int | None) -> CameraPath:
    """``path`` painting what its keyframes key over the film's painting, checked against the scene and the
    work a video may take (its most costly painting on every frame, twice where it cross-fades)."""
    try:
        path = path.with_painting(frame.params, frame.scene.check_names)
    except PathError as exc:
        raise Refusal(str(exc)) from None
    if path.track is None:
        return path
    paintings = path.track.paintings()
    work = max(job_work(frame.width, frame.height, p, temporal, path.frame_count) for p in paintings)
    work *= 2 if path.track.fades else 1
    if work > service.settings.max_video_work:
        raise Refusal(
            f"its keyed painting takes up to {work:,} rays, more than the {service.settings.max_video_work:,} one "
            "video may take: key fewer iterations or samples, or ask for fewer frames or pixels"
        )
    return path


async def scene_named(body: protocol.PathRequest, service: ServiceDep) -> Scene:
    """The scene of a request that paints nothing itself (``POST /api/paths``)."""
    return find_scene(service, body.scene)


# ---- uploads ----

UPLOADS_QUEUED = 3  # uploads reading or waiting to; more are told to come back (each reading takes a core)


def upload_door(service: Service) -> None:
    """Whether an upload may be read now: uploads on, a place among the scenes kept and among those reading;
    else :class:`Refusal` (403, or 503 with a time to try again)."""
    settings, uploads = service.settings, service.uploads
    if not settings.uploads:
        raise Refusal("uploads are off on this server (RCP_UPLOADS=0)", 403)
    service.sweep_uploads()  # before counting
    uploads.check_room(settings.upload_max_scenes, settings.upload_idle_s)
    if uploads.queued >= UPLOADS_QUEUED:
        raise Refusal("other uploads are being read; try again in a few seconds", 503, 5)


def read_upload(body: BinaryIO, filename: str, limits: Limits, keep: Path | None) -> tuple[Scene, int]:
    """Blocking: :func:`~.uploads.read_scene`, its reader's refusal as the service's (the one place it maps)."""
    try:
        return read_scene(body, filename, limits, keep)
    except Refused as exc:
        raise read_refusal(exc) from None


RenderAsked = Annotated[Asked, Depends(render_asked)]
VideoAskedDep = Annotated[VideoAsked, Depends(video_asked)]
SceneDep = Annotated[Scene, Depends(scene_named)]
