"""Video jobs: a camera path painted into an MP4 in the background, watched, fetched and cancelled over REST.

A job paints its frames in order on a thread of its own (at most ``max_videos`` at once; more wait in a
bounded queue), and every frame's tiles go to the background lane of the workshop's shared
:class:`~.workshop.FairPool`: they take the cores the walk-throughs and REST renders leave, so a video never
starves a walk (a walk's tile waits at most for the video tiles in progress). With ``RCP_RAY_ADDRESS`` set, frames
are painted on Ray instead (``cluster.py``) and the local cores stay with the walk-throughs.

Limits (``settings.py``): the work of one job (pixels x samples x iterations, summed over its frames), the
jobs at once, the disk the videos may use, how long a finished video is kept. A job over a limit is refused
at the door (4xx, or 503 when it is only a matter of waiting): a job whose estimated size
(:func:`video_bytes`) does not fit in the disk left, after the finished videos and the estimates of the jobs
queued and running, gets 507 at once. One that still runs out of disk (a video larger than its estimate)
fails with a message.

Jobs outlive the server (``store.py``): each is recorded when submitted, its frames are kept as they finish
(lossless PNGs, and for a temporal job the state the next frame continues from), and the MP4 is assembled from
them at the end. A server that stops (cleanly or ``kill -9``) resumes its queued and running jobs at the next
start from the last frame written, and the film is the uninterrupted run's, frame for frame. The jobs of the
last run count at the door as this run's do: its kept videos by their size, its resumed jobs by their estimate.
"""

from __future__ import annotations

import errno
import itertools
import logging
import math
import shutil
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path
from typing import Literal

import numpy as np

from ..camera.camera import Camera
from ..media.camerapath import CameraPath
from ..media.video import Mp4Writer
from ..painting.loop import Abandoned, PaintState
from ..painting.sequence import frame_params
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .faults import fault_message, report_fault
from .filmfiles import DamagedFrame, file_bytes, folder_bytes, frame_file, kept_frame, save_png, state_bytes
from .memory import Budget, painting_bytes, wait_for_room
from .painter import Painter, PainterFailed
from .refusal import Refusal
from .settings import Settings
from .store import (
    Store,
    UnsafeFile,
    VideoRecord,
    VideoSettings,
    load_state,
    new_video_id,
    real_dir,
    regular_size,
    save_state,
    write_whole,
)
from .workshop import Workshop

log = logging.getLogger("rcp.service")

State = Literal["queued", "running", "done", "failed", "cancelled"]
FINISHED = ("done", "failed", "cancelled")
ANY_CAMERA = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0))
RETRY_AFTER_S = 30  # a full queue of videos frees a place in minutes, not seconds: a fair first guess
BYTES_PER_PIXEL = 0.25
"""An H.264 frame's bytes per pixel at CRF 18, estimated: about three times what a moving painting takes
(0.08 at 320x180); the noisiest styles may take more, which the check while writing still catches."""
MP4_BYTES = 64 * 1024  # the container and the encoder's headers, at most, for the estimate
PNG_BYTES = 1024  # a kept frame's PNG headers and chunks beyond its pixels, at most
PNG_BYTES_PER_PIXEL = 2.0
"""A kept frame's PNG, bytes a pixel, estimated: a painting's smooth strokes deflate to about half their raw RGB;
a noisier one may take more, which the count while writing still catches (507, the frames kept)."""
RAY_ATTEMPTS = 8  # Ray failures a job outlives, waiting each time as Ray backs off (a quarter of an hour in all)


VideoRefused = Refusal  # the one refusal (refusal.py), by the name the films' callers knew


def job_work(width: int, height: int, params: PaintParams, temporal: int | None, frames: int) -> int:
    """Rays x iterations a job paints: pixels x spp x the iterations of every frame (see ``sequence.py``)."""
    iterations = sum(frame_params(params, temporal, k).iterations for k in range(min(frames, 2)))
    iterations += max(frames - 2, 0) * frame_params(params, temporal, 1).iterations
    return width * height * params.spp * iterations


def video_bytes(width: int, height: int, frames: int) -> int:
    """The bytes a video of ``frames`` frames of ``width x height`` is estimated to take on disk at its peak: its
    frames kept as PNGs (:data:`PNG_BYTES_PER_PIXEL`, and a header each) beside the MP4 assembled from them."""
    pngs = frames * (math.ceil(PNG_BYTES_PER_PIXEL * width * height) + PNG_BYTES)
    return MP4_BYTES + math.ceil(BYTES_PER_PIXEL * width * height * frames) + pngs


@dataclass
class VideoJob:
    """One video: what to paint, how far it got, and where its frames and its file are."""

    id: str
    scene_name: str
    scene: Scene | None  # None for a finished job restored from the store: it paints no more
    path: CameraPath
    width: int
    height: int
    params: PaintParams
    temporal: int | None
    file: Path
    frames_dir: Path
    state: State = "queued"
    done_frames: int = 0
    message: str = ""
    created: float = field(default_factory=time.time)  # wall clock: it means the same after a restart
    finished: float | None = None
    cancelled: threading.Event = field(default_factory=threading.Event)
    written: int = 0  # bytes of its frames (and state) on disk, while it paints and once stopped out of disk

    @property
    def frames(self) -> int:
        return self.path.frame_count

    @property
    def estimate(self) -> int:
        """Bytes its video is estimated to take (:func:`video_bytes`)."""
        return video_bytes(self.width, self.height, self.frames)

    def finish(self, state: State, message: str = "") -> None:
        self.state, self.message, self.finished = state, message, time.time()

    def settings(self) -> dict:
        """What the job paints, as JSON the store keeps: :func:`job_of` makes the same job from it."""
        return {
            "path": path_spec(self.path),
            "width": self.width,
            "height": self.height,
            "params": self.params.settings(),
            "temporal": self.temporal,
        }


def path_spec(path: CameraPath) -> dict:
    """A resolved path written out in full (every camera and scene time explicit), so that resolving it again
    gives the same path whatever the scene's camera: JSON keeps every float exactly."""
    keyframes = [  # every camera field (a panorama's projection, stereo and ipd too): none is dropped
        {"t": t, **asdict(c), "scene_time": st}
        for t, c, st in zip(path.times, path.cameras, path.scene_times, strict=True)
    ]
    return {"fps": path.fps, "keyframes": path.keyed(keyframes), "loop": path.loop}


def film_door(
    settings: Settings, camera: Camera, width: int, height: int, params: PaintParams, temporal: int | None, frames: int
) -> tuple[int, int]:
    """Every check of a film's own, for a new job and a stored record alike: its painting's size (both eyes of
    a stereo pair, the pixels one painting may have), even for H.264, and the work of all its frames; the
    painting's size, or :class:`~.refusal.Refusal` (422) in one line."""
    try:
        width, height = settings.painting_size(camera, width, height, params)
    except ValueError as exc:  # CameraError among them
        raise Refusal(str(exc)) from None
    if width % 2 or height % 2:
        raise Refusal(f"an MP4 (H.264, yuv420p) needs an even width and height, got {width}x{height}")
    work = job_work(width, height, params, temporal, frames)
    if work > settings.max_video_work:
        raise Refusal(
            f"{frames} frames of {width}x{height} pixels x {params.spp} spp x their iterations is {work:,} rays, more "
            f"than the {settings.max_video_work:,} one video may take: ask for fewer frames, pixels, samples or "
            "iterations"
        )
    return width, height


def film_bytes(width: int, height: int, path: CameraPath, params: PaintParams, temporal: int | None) -> int:
    """The memory a film's painting holds while it paints: its most costly painting (twice where its keys
    cross-fade), with the frame before kept when it is temporal."""
    paintings = path.track.paintings() if path.track is not None else [params]
    most = max(painting_bytes(p, width, height, kept=2 if temporal else 1) for p in paintings)
    return most * (2 if path.track is not None and path.track.fades else 1)


def job_of(record: VideoRecord, scene: Scene | None, store: Store, settings: Settings) -> VideoJob:
    """The job a stored record describes, checked as a new one is at the door (the same limits: a record is
    untrusted input); ``ValueError`` in one line for one that cannot be painted as it says."""
    given = record.settings
    temporal = given.temporal
    path = given.path.resolve(ANY_CAMERA)  # every keyframe gives its up and fov
    try:
        params = PaintParams(**given.params)
    except TypeError as exc:
        raise ValueError(f"its painting settings: {exc}") from None
    path = path.with_painting(params)  # keyed settings as the door let them through
    camera = path.cameras[0]
    eye = camera.eye_size(given.width, given.height)
    try:
        size = film_door(settings, camera, *eye, params, temporal, path.frame_count)
    except Refusal as refusal:
        raise ValueError(refusal.message) from None
    if size != (given.width, given.height):
        raise ValueError(f"{given.width}x{given.height} is no {camera.stereo} painting")
    return VideoJob(
        record.id,
        record.scene,
        scene,
        path,
        given.width,
        given.height,
        params,
        temporal,
        store.video_file(record.id),
        store.frames_dir(record.id),
        record.state,
        record.done_frames,
        record.message,
        record.created,
        record.finished,
    )


class FilmRun:
    """Paints one job's film: its frames painted (going on after a lost worker), kept on disk as they finish with
    their bytes counted against the videos' disk budget, then assembled into the MP4."""

    def __init__(
        self, settings: Settings, store: Store, painter: Painter, memory: Budget, disk_used: Callable[[], int]
    ):
        self.settings = settings
        self.store = store
        self.painter = painter  # paints the films' frames (the service closes it)
        self.memory = memory  # the paintings' memory, which a film holds while it paints
        self.disk_used = disk_used  # the bytes every video takes, this one among them

    def paint(self, job: VideoJob) -> int:
        """Paints the frames not on disk yet, once its memory is held, and assembles the MP4; its size in bytes."""
        real_dir(job.frames_dir)  # a link in its place is refused: nothing is written through it
        holder, pixels = ("video", job.id), (job.width, job.height)
        nbytes = film_bytes(job.width, job.height, job.path, job.params, job.temporal)
        if not wait_for_room(self.memory, holder, nbytes, pixels, "this video", job.cancelled, self._say(job)):
            raise Abandoned
        self._say(job)("")
        try:
            for attempt in itertools.count(1):
                try:
                    self._paint_frames(job)
                    break
                except PainterFailed as exc:  # its workers were lost: the job goes on from its last frame
                    if attempt >= RAY_ATTEMPTS or exc.retry_s is None:  # the latter would fail again
                        raise
                    wait = exc.retry_s
                    self._say(job)(f"{exc}; going on from frame {job.done_frames} in {math.ceil(wait)} s")
                    if job.cancelled.wait(wait):
                        raise Abandoned from None
                    job.message = ""
        finally:
            self.memory.release(holder)
        self._assemble(job)
        size = regular_size(job.file) or 0
        if size + self.disk_used() > self.settings.video_disk_bytes:  # the finished videos and this one
            job.file.unlink(missing_ok=True)
            raise OSError(
                errno.ENOSPC, f"the videos would use more than the {self.settings.video_disk_bytes:,} bytes allowed"
            )
        return size

    def _paint_frames(self, job: VideoJob) -> None:
        """Paints the frames not on disk yet, keeping each as it finishes (and a temporal job's state)."""
        start, previous = self._resume_point(job)
        if start > 0:
            log.info("video %s resumes at frame %d of %d", job.id, start, job.frames)
        job.done_frames = start
        job.written = folder_bytes(job.frames_dir)  # counted once here, then frame by frame
        state_file = job.frames_dir / "state.npz"
        for image, state in self._paintings(job, start, previous):
            frame, kept = frame_file(job.frames_dir, job.done_frames), file_bytes(state_file)
            write_whole(frame, partial(save_png, image))
            if state is not None:
                save_state(state_file, job.done_frames, state)
            job.written += file_bytes(frame) + file_bytes(state_file) - kept
            if self.disk_used() > self.settings.video_disk_bytes:  # this frame would pass the bound: it goes
                job.written -= file_bytes(frame)
                frame.unlink(missing_ok=True)
                raise self._out_of_disk(job)
            job.done_frames += 1
            self.store.update_video(job.id, done_frames=job.done_frames)

    def _say(self, job: VideoJob) -> Callable[[str], None]:
        """What the job's status says while it waits (for memory, for Ray), kept with its record."""

        def say(message: str) -> None:
            job.message = message
            self.store.update_video(job.id, message=message)

        return say

    def _out_of_disk(self, job: VideoJob) -> Refusal:
        limit = self.settings.video_disk_bytes
        return Refusal(
            f"the videos would use more than the {limit:,} bytes of RCP_VIDEO_DISK_BYTES: stopped after "
            f"{job.done_frames} frames, kept until the video expires or is deleted",
            507,
        )

    def _resume_point(self, job: VideoJob) -> tuple[int, PaintState | None]:
        """The first frame still to paint (the frames before it are on disk), and for a temporal job painted
        here the state it continues from. A frame written without its state is painted again."""
        written = 0
        while written < job.frames and regular_size(frame_file(job.frames_dir, written)) is not None:
            written += 1
        if not job.temporal or written == 0:
            return written, None
        saved = load_state(job.frames_dir / "state.npz", state_bytes(job.width, job.height))
        if saved is not None and saved[0] in (written - 1, written - 2):
            index, state = saved
            if index == written - 2:  # stopped between the frame and its state: that frame is painted again
                frame_file(job.frames_dir, written - 1).unlink(missing_ok=True)
            return index + 1, state
        return written, None  # no state to go on from (a painter that keeps it, as Ray's bands do): painted again

    def _paintings(
        self, job: VideoJob, start: int, previous: PaintState | None
    ) -> Iterator[tuple[np.ndarray, PaintState | None]]:
        """The frames from ``start`` on, each (height, width, 3) uint8, with the state a temporal job continues
        from (None when nothing needs keeping)."""
        if start >= job.frames:
            return
        scene = job.scene
        assert scene is not None

        def stop() -> bool:
            return job.cancelled.is_set()

        yield from self.painter.film(
            scene, job.path, job.width, job.height, job.params, job.temporal, start, previous, stop
        )

    def _assemble(self, job: VideoJob) -> None:
        """The MP4 of the frames on disk, in one pass of the encoder (as an uninterrupted run encodes them)."""
        camera = job.path.cameras[0]  # a path keeps one projection: its frames are all laid out alike
        writer = Mp4Writer(job.file, job.width, job.height, job.path.fps, camera.projection, camera.stereo)
        try:
            for k in range(job.frames):
                if job.cancelled.is_set():
                    raise Abandoned
                writer.write(kept_frame(job.frames_dir, k, job.width, job.height))
            writer.close()
        except BaseException:
            writer.abort()
            raise


class Videos:
    """The video jobs of one server: submitted, run, kept for ``video_keep_s`` once finished, then dropped; all
    of it recorded in ``store`` so that a restart resumes where the last run stopped (:meth:`resume`)."""

    def __init__(self, settings: Settings, workshop: Workshop, store: Store, painter: Painter, memory: Budget):
        self.settings = settings
        self.workshop = workshop  # whether the server is stopping
        self.store = store
        self.painter = painter  # paints the films' frames (the service closes it)
        self.memory = memory
        self.run = FilmRun(settings, store, painter, memory, self.disk_used)
        self._jobs: dict[str, VideoJob] = {}
        self._lock = threading.Lock()
        self._closing = False  # stopping the server: jobs in progress stay recorded as they are, to resume
        self._runners = ThreadPoolExecutor(settings.max_videos, thread_name_prefix="rcp-video")

    def resume(self, scene_of: Callable[[str], Scene | None]) -> None:
        """At start-up: the stored jobs back, the finished ones to be fetched, the others queued again to go on
        from their last frame written (a job whose scene is gone fails, saying so)."""
        for record in self.store.videos():
            scene = scene_of(record.scene) if record.state not in FINISHED else None
            try:
                job = job_of(record, scene, self.store, self.settings)
            except ValueError as exc:  # a record that cannot be painted as it says: dropped with its files
                log.warning("data folder %s: video %s dropped: %s", self.store.folder, record.id, exc)
                self.store.remove_video(record.id)
                continue
            self._jobs[job.id] = job
            if job.state == "failed":  # stopped out of disk: its frames are kept, and counted, until it expires
                job.written = folder_bytes(job.frames_dir)
            if job.state in FINISHED:
                if job.state == "done" and regular_size(job.file) is None:
                    self._finish(job, "failed", "its file was lost while the server was down")
                continue
            if scene is None:
                self._finish(job, "failed", f"its scene {record.scene!r} is gone (removed while the server was down)")
                continue
            job.state = "queued"
            self.store.update_video(job.id, state="queued")
            log.info("video %s queued again, %d of its %d frames written", job.id, job.done_frames, job.frames)
            self._runners.submit(self._run, job)

    # ---- the door ----

    def submit(
        self, scene: Scene, path: CameraPath, width: int, height: int, params: PaintParams, temporal: int | None
    ) -> VideoJob:
        """Queue a job of ``width x height`` eye images (a stereo film's frames hold two), or refuse it
        (:class:`~.refusal.Refusal`: 422 over a limit (:func:`film_door`), 507 the disk budget used up, 503 every
        place in the queue taken)."""
        settings = self.settings
        width, height = film_door(settings, path.cameras[0], width, height, params, temporal, path.frame_count)
        self.memory.check(film_bytes(width, height, path, params, temporal), (width, height), "this video")
        self.sweep()
        job_id = new_video_id()
        store = self.store
        job = VideoJob(
            job_id, scene.name, scene, path, width, height, params, temporal, store.video_file(job_id),
            store.frames_dir(job_id),
        )  # fmt: skip
        with self._lock:
            waiting = [j for j in self._jobs.values() if j.state in ("queued", "running")]
            room = settings.video_disk_bytes - self.disk_used() - sum(j.estimate for j in waiting)
            if job.estimate > room:
                raise Refusal(
                    f"the video would take about {job.estimate:,} bytes and the videos have {max(room, 0):,} of "
                    f"their {settings.video_disk_bytes:,} left (RCP_VIDEO_DISK_BYTES, with the videos in progress): "
                    f"ask for fewer frames or pixels, delete videos (DELETE /api/videos/ID) or wait until they "
                    f"expire ({settings.video_keep_s:g} s after they finish)",
                    507,
                )
            if len(waiting) >= settings.max_videos + settings.max_videos_waiting:
                message = f"the video queue is busy, every place in it taken; try again in {RETRY_AFTER_S} s"
                raise Refusal(message, 503, RETRY_AFTER_S)
            self._jobs[job_id] = job
        store.add_video(
            VideoRecord(
                id=job.id,
                scene=job.scene_name,
                settings=VideoSettings.model_validate(job.settings()),
                frames=job.frames,
                state=job.state,
                done_frames=0,
                message="",
                created=job.created,
                finished=None,
                bytes=0,
            )
        )
        self._runners.submit(self._run, job)
        return job

    def get(self, job_id: str) -> VideoJob | None:
        self.sweep()
        return self._jobs.get(job_id)

    def delete(self, job_id: str) -> VideoJob | None:
        """Cancel a job in progress (it stops at its next tile; cancelled, it stays to be seen until it expires, and
        cancelling it again changes nothing); forget a finished one and delete its file."""
        job = self._jobs.get(job_id)
        if job is None:
            return None
        with self._lock:
            if job.state == "cancelled" or job.cancelled.is_set():
                return job
            if job.state in FINISHED:
                self._jobs.pop(job_id, None)
                self.store.remove_video(job_id)
                return job
            job.cancelled.set()
            if job.state == "queued":
                self._finish(job, "cancelled", "cancelled before it started")
        return job

    def scenes_in_progress(self) -> list[Scene]:
        """The scenes of the jobs queued or painting, or finished less than ``upload_idle_s`` ago (an uploaded
        one among them is in use: a job uses its scene up to its end, and a job that ended before anyone
        looked must not leave its scene idle since long before)."""
        recent = time.time() - self.settings.upload_idle_s
        return [
            j.scene
            for j in list(self._jobs.values())
            if j.scene is not None and (j.state not in FINISHED or (j.finished or 0.0) > recent)
        ]

    # ---- the work ----

    def _run(self, job: VideoJob) -> None:
        with self._lock:
            if job.state != "queued" or self._closing:  # cancelled while it waited, or the server is stopping
                return
            job.state = "running"
        self.store.update_video(job.id, state="running")
        try:
            size = self.run.paint(job)
            self._finish(job, "done", f"{job.frames} frames, {size:,} bytes")
        except Exception as exc:
            if self._closing or self.workshop.stopping:  # recorded as it was: the next start goes on from here
                return
            if isinstance(exc, Abandoned) or job.cancelled.is_set():
                self._finish(job, "cancelled", "cancelled")
            elif isinstance(exc, UnsafeFile):  # its files in the data folder were tampered with
                self._finish(job, "failed", str(exc))
            elif isinstance(exc, OSError):  # the disk: full, or over the budget; said without the server's paths
                log.warning("video %s: cannot write the video: %s", job.id, exc)
                self._finish(job, "failed", f"cannot write the video: {exc.strerror or 'see the server log'}")
            elif isinstance(exc, Refusal):  # out of disk: what it made is kept (and counted) until it expires
                self._finish(job, "failed", f"{exc.status}: {exc.message}", keep=True)
            elif isinstance(exc, DamagedFrame):
                self._finish(job, "failed", str(exc))
            elif isinstance(exc, PainterFailed):  # Ray: no answer at its address, a worker lost
                self._finish(job, "failed", str(exc))
            else:
                self._finish(job, "failed", fault_message(report_fault(f"video {job.id}: {exc}")))

    def _finish(self, job: VideoJob, state: State, message: str = "", keep: bool = False) -> None:
        """``keep``: its frames stay on disk (and count) until the job expires or is deleted."""
        job.finish(state, message)
        size = file_bytes(job.file) if state == "done" else job.written if keep else 0
        self.store.update_video(job.id, state=state, message=message, finished=job.finished, bytes=size)
        if not keep:
            shutil.rmtree(job.frames_dir, ignore_errors=True)
            job.written = 0
        if state != "done":
            job.file.unlink(missing_ok=True)

    # ---- keeping house ----

    def disk_used(self) -> int:
        """Bytes the videos take: the finished ones kept, and every byte a film in progress (or stopped, its
        frames kept) has written."""
        return sum(file_bytes(j.file) if j.state == "done" else j.written for j in list(self._jobs.values()))

    def sweep(self) -> None:
        """Forget the jobs finished more than ``video_keep_s`` ago, and delete their files."""
        now = time.time()
        with self._lock:
            old = [
                j
                for j in self._jobs.values()
                if j.finished is not None and now - j.finished > self.settings.video_keep_s
            ]
            for job in old:
                del self._jobs[job.id]
        for job in old:
            self.store.remove_video(job.id)

    def close(self) -> None:
        """Stop every job at its next tile, and wait for the runners: what they wrote stays, recorded, for the
        next start to go on from."""
        self._closing = True
        for job in list(self._jobs.values()):
            job.cancelled.set()
        self._runners.shutdown(wait=True, cancel_futures=True)
