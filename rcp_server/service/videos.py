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
"""

from __future__ import annotations

import logging
import math
import secrets
import shutil
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from ..camerapath import CameraPath
from ..cluster import ClusterError
from ..painting import Abandoned, PaintState
from ..params import PaintParams
from ..scene import Scene
from ..sequence import frame_params, paint_sequence
from ..video import Mp4Writer
from .faults import fault_message, report_fault
from .settings import Settings
from .workshop import Busy, Workshop

log = logging.getLogger("rcp.service")

State = Literal["queued", "running", "done", "failed", "cancelled"]
FINISHED = ("done", "failed", "cancelled")
RETRY_AFTER_S = 30  # a full queue of videos frees a place in minutes, not seconds: a fair first guess
BYTES_PER_PIXEL = 0.25
"""An H.264 frame's bytes per pixel at CRF 18, estimated: about three times what a moving painting takes
(0.08 at 320x180); the noisiest styles may take more, which the check while writing still catches."""
MP4_BYTES = 64 * 1024  # the container and the encoder's headers, at most, for the estimate


class VideoRefused(ValueError):
    """A job that cannot be taken as asked (over a limit, out of disk budget); said to the caller in one line."""

    def __init__(self, message: str, status: int = 422):
        super().__init__(message)
        self.status = status


def job_work(width: int, height: int, params: PaintParams, temporal: int | None, frames: int) -> int:
    """Rays x iterations a job paints: pixels x spp x the iterations of every frame (see ``sequence.py``)."""
    iterations = sum(frame_params(params, temporal, k).iterations for k in range(min(frames, 2)))
    iterations += max(frames - 2, 0) * frame_params(params, temporal, 1).iterations
    return width * height * params.spp * iterations


def video_bytes(width: int, height: int, frames: int) -> int:
    """The bytes a video of ``frames`` frames of ``width x height`` is estimated to take on disk."""
    return MP4_BYTES + math.ceil(BYTES_PER_PIXEL * width * height * frames)


@dataclass
class VideoJob:
    """One video: what to paint, how far it got, and where its file is once done."""

    id: str
    scene: Scene
    path: CameraPath
    width: int
    height: int
    params: PaintParams
    temporal: int | None
    file: Path
    state: State = "queued"
    done_frames: int = 0
    message: str = ""
    created: float = field(default_factory=time.monotonic)
    finished: float | None = None
    cancelled: threading.Event = field(default_factory=threading.Event)

    @property
    def frames(self) -> int:
        return self.path.frame_count

    @property
    def estimate(self) -> int:
        """Bytes its video is estimated to take (:func:`video_bytes`)."""
        return video_bytes(self.width, self.height, self.frames)

    def finish(self, state: State, message: str = "") -> None:
        self.state, self.message, self.finished = state, message, time.monotonic()


class Videos:
    """The video jobs of one server: submitted, run, kept for ``video_keep_s`` once finished, then dropped."""

    def __init__(self, settings: Settings, workshop: Workshop, painter=None):
        self.settings = settings
        self.workshop = workshop
        self.painter = painter  # a cluster.RayPainter (the service closes it), or None: the workshop's shared pool
        own = settings.video_dir is None
        self.folder = Path(tempfile.mkdtemp(prefix="rcp-videos-")) if settings.video_dir is None else settings.video_dir
        self.folder.mkdir(parents=True, exist_ok=True)
        self._own_folder = own
        self._jobs: dict[str, VideoJob] = {}
        self._lock = threading.Lock()
        self._runners = ThreadPoolExecutor(settings.max_videos, thread_name_prefix="rcp-video")

    # ---- the door ----

    def submit(
        self, scene: Scene, path: CameraPath, width: int, height: int, params: PaintParams, temporal: int | None
    ) -> VideoJob:
        """Queue a job, or refuse it: :class:`VideoRefused` (over a limit, the disk budget used up) or
        :class:`~.workshop.Busy` (every place in the queue taken)."""
        settings = self.settings
        settings.check_painting(width, height, params)
        work = job_work(width, height, params, temporal, path.frame_count)
        if work > settings.max_video_work:
            raise VideoRefused(
                f"{path.frame_count} frames of {width}x{height} pixels x {params.spp} spp x their iterations is "
                f"{work:,} rays, more than the {settings.max_video_work:,} one video may take: ask for fewer "
                "frames, pixels, samples or iterations"
            )
        self.sweep()
        job_id = secrets.token_hex(8)
        job = VideoJob(job_id, scene, path, width, height, params, temporal, self.folder / f"{job_id}.mp4")
        with self._lock:
            waiting = [j for j in self._jobs.values() if j.state in ("queued", "running")]
            room = settings.video_disk_bytes - self.disk_used() - sum(j.estimate for j in waiting)
            if job.estimate > room:
                raise VideoRefused(
                    f"the video would take about {job.estimate:,} bytes and the videos have {max(room, 0):,} of "
                    f"their {settings.video_disk_bytes:,} left (RCP_VIDEO_DISK_BYTES, with the videos in progress): "
                    f"ask for fewer frames or pixels, delete videos (DELETE /api/videos/ID) or wait until they "
                    f"expire ({settings.video_keep_s:g} s after they finish)",
                    507,
                )
            if len(waiting) >= settings.max_videos + settings.max_videos_waiting:
                raise Busy(RETRY_AFTER_S)
            self._jobs[job_id] = job
        self._runners.submit(self._run, job)
        return job

    def get(self, job_id: str) -> VideoJob | None:
        self.sweep()
        return self._jobs.get(job_id)

    def delete(self, job_id: str) -> VideoJob | None:
        """Cancel a job in progress (it stops at its next tile); forget a finished one and delete its file."""
        job = self._jobs.get(job_id)
        if job is None:
            return None
        with self._lock:
            if job.state in FINISHED:
                self._jobs.pop(job_id, None)
                job.file.unlink(missing_ok=True)
                return job
            job.cancelled.set()
            if job.state == "queued":
                job.finish("cancelled", "cancelled before it started")
        return job

    # ---- the work ----

    def _run(self, job: VideoJob) -> None:
        with self._lock:
            if job.state != "queued":  # cancelled while it waited
                return
            job.state = "running"
        writer = None
        try:
            writer = Mp4Writer(job.file, job.width, job.height, job.path.fps)
            for image in self._paintings(job):
                writer.write(image)
                job.done_frames += 1
                self._check_disk(writer.size())
            writer.close()
            try:
                self._check_disk(writer.size())  # the encoder's last packets and the index come at the end
            except OSError:
                job.file.unlink(missing_ok=True)
                raise
            job.finish("done", f"{job.frames} frames, {job.file.stat().st_size:,} bytes")
        except Abandoned:
            message = "the server is stopping" if self.workshop.stopping else "cancelled"
            job.finish("failed" if self.workshop.stopping else "cancelled", message)
        except OSError as exc:  # the disk: full, or over the budget
            job.finish("failed", f"cannot write the video: {exc.strerror or exc}")
        except ClusterError as exc:  # Ray: no answer at its address, a worker lost
            job.finish("failed", str(exc))
        except Exception as exc:
            if job.cancelled.is_set():
                job.finish("cancelled", "cancelled")
            else:
                job.finish("failed", fault_message(report_fault(f"video {job.id}: {exc}")))
        finally:
            if job.state != "done" and writer is not None:
                writer.abort()

    def _paintings(self, job: VideoJob):
        def stop() -> bool:
            return job.cancelled.is_set()

        if self.painter is not None:
            yield from self.painter.images(
                job.scene, job.path.frames(), job.width, job.height, job.params, job.temporal, should_stop=stop
            )
            return

        def paint_frame(camera, scene_time: float, params: PaintParams, previous: PaintState | None):
            return self.workshop.paint(
                job.scene,
                camera,
                job.width,
                job.height,
                params,
                should_stop=stop,
                background=True,
                time=scene_time,
                previous=previous,
            )

        yield from paint_sequence(paint_frame, job.path.frames(), job.params, job.temporal)

    def _check_disk(self, writing: int) -> None:
        if writing + self.disk_used() > self.settings.video_disk_bytes:
            raise OSError(f"the videos would use more than the {self.settings.video_disk_bytes:,} bytes allowed")

    # ---- keeping house ----

    def disk_used(self) -> int:
        """Bytes of the finished videos kept (a video in progress counts once it is done)."""
        return sum(_size(j.file) for j in list(self._jobs.values()) if j.state == "done")

    def sweep(self) -> None:
        """Forget the jobs finished more than ``video_keep_s`` ago, and delete their files."""
        now = time.monotonic()
        with self._lock:
            old = [
                j
                for j in self._jobs.values()
                if j.finished is not None and now - j.finished > self.settings.video_keep_s
            ]
            for job in old:
                del self._jobs[job.id]
        for job in old:
            job.file.unlink(missing_ok=True)

    def close(self) -> None:
        """Cancel every job, wait for the runners, and remove the folder if this server made it."""
        for job in list(self._jobs.values()):
            job.cancelled.set()
        self._runners.shutdown(wait=True, cancel_futures=True)
        if self._own_folder:
            shutil.rmtree(self.folder, ignore_errors=True)


def _size(file: Path) -> int:
    try:
        return file.stat().st_size
    except OSError:  # deleted meanwhile
        return 0
