"""Print jobs (``/api/prints``): a still at print size (``media/prints.py``) painted in the background on the
workshop's background lane, band by band, into a PNG of the data folder, then fetched; with progress (rows
painted), cancel, and limits: its work within ``RCP_MAX_PRINT_WORK``, its file within what
``RCP_VIDEO_DISK_BYTES`` leaves after the videos and the prints kept or under way. A finished print is kept
``RCP_VIDEO_KEEP_S`` seconds. Prints are not resumed after a restart: the folder is emptied as the server
starts.
"""

from __future__ import annotations

import logging
import shutil
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from ..camera.camera import Camera
from ..media import prints
from ..painting.loop import Abandoned
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .memory import Budget, painting_bytes, wait_for_room
from .refusal import Refusal
from .settings import Settings
from .store import new_video_id
from .workshop import Workshop

log = logging.getLogger("rcp")
State = Literal["queued", "running", "done", "failed", "cancelled"]
FINISHED = ("done", "failed", "cancelled")
PNG_OVERHEAD = 1 << 16  # the PNG's headers and zlib's worst case over the raw rows, bytes
RETRY_AFTER_S = 10


def print_work(width: int, height: int, params: PaintParams, alpha: bool) -> int:
    """Rays x iterations a print paints: every pixel, sample and iteration, and the plain pass of its alpha."""
    return width * height * params.spp * (params.iterations + (1 if alpha else 0))


def print_bytes(width: int, height: int, bits: int, alpha: bool) -> int:
    """The most a print's PNG takes: its rows uncompressed, each with its filter byte, and the overhead."""
    return height * (1 + width * (4 if alpha else 3) * bits // 8) + PNG_OVERHEAD


@dataclass
class PrintJob:
    id: str
    scene: Scene
    camera: Camera
    width: int
    height: int
    params: PaintParams
    time: float
    bits: int
    alpha: bool
    file: Path
    state: State = "queued"
    done_rows: int = 0
    message: str = ""
    finished: float | None = None
    cancelled: threading.Event = field(default_factory=threading.Event)

    @property
    def estimate(self) -> int:
        return print_bytes(self.width, self.height, self.bits, self.alpha)


class Prints:
    """The print jobs of one server: one painted at a time, a few waiting, each kept a while once finished."""

    def __init__(
        self, settings: Settings, workshop: Workshop, memory: Budget, folder: Path, disk_used_by_videos=lambda: 0
    ):
        self.settings = settings
        self.workshop = workshop
        self.memory = memory  # the paintings' memory: a print holds its largest band's while it paints
        self.folder = Path(folder)
        shutil.rmtree(self.folder, ignore_errors=True)  # prints do not outlive a restart
        self.folder.mkdir(parents=True, exist_ok=True)
        self._videos_disk = disk_used_by_videos
        self._jobs: dict[str, PrintJob] = {}
        self._lock = threading.Lock()
        self._runner = ThreadPoolExecutor(1, thread_name_prefix="rcp-print")

    def submit(
        self, scene: Scene, camera: Camera, width: int, height: int, params: PaintParams, time_s: float, bits: int,
        alpha: bool,
    ) -> PrintJob:  # fmt: skip
        """Queue a print or refuse it: ``ValueError`` (a print that cannot be made), :class:`~.refusal.Refusal` (over
        the work limit, 422; or the disk, 507) (503: the queue full)."""
        prints.check_print(width, height, params, bits)
        work = print_work(width, height, params, alpha)
        if work > self.settings.max_print_work:
            raise Refusal(
                f"{width}x{height} pixels x {params.spp} spp x their iterations is {work:,} rays, more than the "
                f"{self.settings.max_print_work:,} one print may take (RCP_MAX_PRINT_WORK)"
            )
        band = prints.bands(width, height)[0]
        self.memory.check(painting_bytes(params, band.width, band.height), (band.width, band.height), "a band of it")
        self.sweep()
        job_id = new_video_id()
        job = PrintJob(job_id, scene, camera, width, height, params, time_s, bits, alpha, self.folder / f"{job_id}.png")
        with self._lock:
            waiting = [j for j in self._jobs.values() if j.state in ("queued", "running")]
            kept = sum(_size(j.file) for j in self._jobs.values() if j.state == "done")
            room = self.settings.video_disk_bytes - self._videos_disk() - kept - sum(j.estimate for j in waiting)
            if job.estimate > room:
                raise Refusal(
                    f"the print may take {job.estimate:,} bytes and the videos and prints have {max(room, 0):,} of "
                    f"their {self.settings.video_disk_bytes:,} left (RCP_VIDEO_DISK_BYTES): ask for fewer pixels, "
                    "or wait until others expire",
                    507,
                )
            if len(waiting) > self.settings.max_videos_waiting:
                raise Refusal("other prints are waiting; try again later", 503, RETRY_AFTER_S)
            self._jobs[job_id] = job
        self._runner.submit(self._run, job)
        return job

    def _run(self, job: PrintJob) -> None:
        band = prints.bands(job.width, job.height)[0]  # the first is the largest
        nbytes = painting_bytes(job.params, band.width, band.height)
        holder, size = ("print", job.id), (band.width, band.height)
        try:
            if not wait_for_room(self.memory, holder, nbytes, size, "a band of this print", job.cancelled,
                                 lambda line: setattr(job, "message", line)):  # fmt: skip
                return
        except Refusal as refusal:  # a band that can never fit
            self._finish(job, "failed", refusal.message)
            return
        job.message = ""
        try:
            self._paint(job)
        finally:
            self.memory.release(holder)

    def _paint(self, job: PrintJob) -> None:
        if job.cancelled.is_set():
            return
        job.state = "running"

        def paint_band(band, params: PaintParams):
            return self.workshop.paint(job.scene, job.camera, job.width, job.height, params,
                                       should_stop=job.cancelled.is_set, background=True, time=job.time,
                                       region=band)  # fmt: skip

        def progress(rows: int) -> None:
            job.done_rows += rows

        try:
            rows = prints.print_bands(job.scene, job.camera, job.width, job.height, job.params, paint_band,
                                      time=job.time, bits=job.bits, alpha=job.alpha)  # fmt: skip
            prints.write_print(job.file, rows, job.width, job.height, job.bits, job.alpha, progress)
        except Abandoned:
            self._finish(job, "cancelled", "cancelled")
        except (ValueError, OSError, MemoryError) as exc:
            log.warning("print %s failed: %s", job.id, exc)
            self._finish(job, "failed", str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        else:
            self._finish(job, "cancelled" if job.cancelled.is_set() else "done")

    def _finish(self, job: PrintJob, state: State, message: str = "") -> None:
        job.state, job.message, job.finished = state, message, time.time()
        if state != "done":
            job.file.unlink(missing_ok=True)

    def get(self, job_id: str) -> PrintJob | None:
        self.sweep()
        return self._jobs.get(job_id)

    def delete(self, job_id: str) -> PrintJob | None:
        """Cancel a print in progress (it stops within a tile), or forget a finished one and its file."""
        with self._lock:
            job = self._jobs.get(job_id)
            if job is None:
                return None
            if job.state in FINISHED:
                del self._jobs[job_id]
                job.file.unlink(missing_ok=True)
                return job
        job.cancelled.set()
        if job.state == "queued":
            self._finish(job, "cancelled", "cancelled")
        return job

    def sweep(self) -> None:
        """Forget the prints finished more than ``video_keep_s`` ago, and their files."""
        now = time.time()
        with self._lock:
            for job_id, job in list(self._jobs.items()):
                if job.finished is not None and now - job.finished > self.settings.video_keep_s:
                    del self._jobs[job_id]
                    job.file.unlink(missing_ok=True)

    def close(self) -> None:
        for job in list(self._jobs.values()):
            job.cancelled.set()
        self._runner.shutdown(wait=True, cancel_futures=True)


def _size(file: Path) -> int:
    try:
        return file.stat().st_size
    except OSError:
        return 0
