"""The data folder (``RCP_DATA``): what a server keeps across restarts, and the one module that writes it.

::

    RCP_DATA/
      lock             held (``flock``) by the one server using the folder, its pid inside
      rcp.sqlite       the records, in SQLite (WAL mode: a reader never waits for a writer)
      uploads/NAME/    an uploaded model: the file as it came (``original``) and its parsed arrays (``parts.npz``)
      videos/ID.mp4    a finished video
      videos/ID/       a video job's frames as they finish (``frame_000000.png``, lossless), and for a temporal
                       job the painting state the next frame continues from (``state.npz``)

Records hold wall-clock times (``time.time()``, seconds): they must mean the same after a restart. A record is
written after the files it describes, so a ``kill -9`` at any point leaves files without a record (removed at
the next start), never a record without its files.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import shutil
import sqlite3
import threading
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from ..camera.camera import Region
from ..engine.paintstate import CHANNELS, PaintState

log = logging.getLogger("rcp.service")

SCHEMA = """
CREATE TABLE IF NOT EXISTS uploads (
    name TEXT PRIMARY KEY,
    title TEXT NOT NULL,
    owner TEXT,                -- sha256 of the token the upload came with, if any
    file_bytes INTEGER NOT NULL,
    weight INTEGER NOT NULL,   -- bytes the scene takes in memory once loaded
    created REAL NOT NULL,
    used REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS videos (
    id TEXT PRIMARY KEY,
    scene TEXT NOT NULL,
    settings TEXT NOT NULL,    -- JSON: the resolved path, size, painting settings, temporal
    frames INTEGER NOT NULL,
    state TEXT NOT NULL,
    done_frames INTEGER NOT NULL,
    message TEXT NOT NULL,
    created REAL NOT NULL,
    finished REAL,
    bytes INTEGER NOT NULL     -- of the finished file
);
"""


class DataFolderError(RuntimeError):
    """The data folder cannot be used (another server holds it, or it cannot be written); one line, said at
    start-up."""


@dataclass(frozen=True)
class UploadRecord:
    name: str
    title: str
    owner: str | None
    file_bytes: int
    weight: int
    created: float
    used: float


@dataclass(frozen=True)
class VideoRecord:
    id: str
    scene: str
    settings: dict
    frames: int
    state: str
    done_frames: int
    message: str
    created: float
    finished: float | None
    bytes: int


class Store:
    """The data folder of one server: holds its lock and its database connection (every thread shares both,
    one statement at a time). ``close`` lets go of the folder."""

    def __init__(self, folder: Path):
        self.folder = Path(folder).expanduser()
        self.uploads_dir = self.folder / "uploads"
        self.videos_dir = self.folder / "videos"
        try:
            for path in (self.folder, self.uploads_dir, self.videos_dir):
                path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DataFolderError(f"cannot use the data folder {self.folder}: {exc.strerror or exc}") from None
        self._lock_file = _lock(self.folder / "lock")
        try:
            self._db = sqlite3.connect(self.folder / "rcp.sqlite", check_same_thread=False, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")  # WAL: a power cut may lose the last records, not corrupt
            self._db.executescript(SCHEMA)
        except sqlite3.Error as exc:
            self._lock_file.close()
            raise DataFolderError(f"cannot use the records in {self.folder / 'rcp.sqlite'}: {exc}") from None
        self._mutex = threading.Lock()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        with self._mutex:
            self._db.close()
        self._lock_file.close()  # closing the descriptor lets go of the flock

    def _run(self, sql: str, args: tuple = ()) -> list[tuple]:
        with self._mutex:
            return self._db.execute(sql, args).fetchall()

    # ---- uploads ----

    def upload_dir(self, name: str) -> Path:
        return self.uploads_dir / name

    def add_upload(self, record: UploadRecord) -> None:
        """Records an upload whose files are in :meth:`upload_dir` already."""
        self._run(f"INSERT OR REPLACE INTO uploads VALUES ({_marks(UploadRecord)})", astuple(record))

    def uploads(self) -> list[UploadRecord]:
        return [UploadRecord(*row) for row in self._run("SELECT * FROM uploads ORDER BY created")]

    def touch_upload(self, name: str, used: float) -> None:
        self._run("UPDATE uploads SET used = ? WHERE name = ?", (used, name))

    def remove_upload(self, name: str) -> None:
        """The record first, then the files: a crash in between leaves files that the next start removes."""
        self._run("DELETE FROM uploads WHERE name = ?", (name,))
        shutil.rmtree(self.upload_dir(name), ignore_errors=True)

    # ---- videos ----

    def video_file(self, video_id: str) -> Path:
        return self.videos_dir / f"{video_id}.mp4"

    def frames_dir(self, video_id: str) -> Path:
        return self.videos_dir / video_id

    def add_video(self, record: VideoRecord) -> None:
        self._run(f"INSERT INTO videos VALUES ({_marks(VideoRecord)})", astuple(record))

    def update_video(self, video_id: str, **values) -> None:
        names = ", ".join(f"{name} = ?" for name in values)
        self._run(f"UPDATE videos SET {names} WHERE id = ?", (*values.values(), video_id))

    def videos(self) -> list[VideoRecord]:
        rows = self._run("SELECT * FROM videos ORDER BY created")
        names = [f.name for f in fields(VideoRecord)]
        records = [dict(zip(names, row, strict=True)) for row in rows]
        return [VideoRecord(**{**record, "settings": json.loads(record["settings"])}) for record in records]

    def remove_video(self, video_id: str) -> None:
        self._run("DELETE FROM videos WHERE id = ?", (video_id,))
        self.video_file(video_id).unlink(missing_ok=True)
        shutil.rmtree(self.frames_dir(video_id), ignore_errors=True)

    # ---- keeping house ----

    def remove_strays(self) -> None:
        """Files no record describes (a crash between writing them and recording them): removed."""
        uploads = {record.name for record in self.uploads()}
        for path in self.uploads_dir.iterdir():
            if path.name not in uploads:
                shutil.rmtree(path, ignore_errors=True)
        videos = {record.id for record in self.videos()}
        for path in self.videos_dir.iterdir():
            if path.name.split(".")[0] not in videos and path.name.lstrip(".").split(".")[0] not in videos:
                shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)


def astuple(record) -> tuple:
    values = asdict(record)
    if "settings" in values:
        values["settings"] = json.dumps(values["settings"])
    return tuple(values.values())


def _marks(record_type) -> str:
    return ", ".join("?" for _ in fields(record_type))


def _lock(path: Path):
    """The folder's lock, held for as long as the returned file is open; :class:`DataFolderError` if another
    process holds it (a lock the kernel drops with its holder: a ``kill -9`` leaves nothing stale)."""
    handle = open(path, "a+")  # noqa: SIM115 (held open for the server's lifetime)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.seek(0)
        holder = handle.read().strip() or "unknown"
        handle.close()
        raise DataFolderError(
            f"the data folder {path.parent} is in use by another server (pid {holder}); give this one its own RCP_DATA"
        ) from None
    handle.seek(0)
    handle.truncate()
    handle.write(str(os.getpid()))
    handle.flush()
    return handle


# ---- files written whole ----


def write_whole(path: Path, write) -> None:
    """``write(temporary_path)``, then the file moved into place: a reader (or a restart) sees it whole or not at
    all."""
    partial = path.with_name(f".{path.name}.part")
    write(partial)
    os.replace(partial, path)


def save_state(path: Path, index: int, state: PaintState) -> None:
    """The painting state after frame ``index`` of a temporal video, whole (see :func:`write_whole`)."""
    arrays = {name: getattr(state, name) for name in CHANNELS if getattr(state, name) is not None}
    region = np.array([getattr(state.region, f.name) for f in fields(Region)], np.int64)

    def write(partial: Path) -> None:
        with open(partial, "wb") as sink:
            np.savez(sink, index=np.int64(index), region=region, blank=np.bool_(state.blank), **arrays)

    write_whole(path, write)


def load_state(path: Path) -> tuple[int, PaintState] | None:
    """The frame index and state :func:`save_state` wrote, None if there is none."""
    with contextlib.suppress(OSError, ValueError, KeyError):
        with np.load(path, allow_pickle=False) as saved:
            region = Region(*(int(v) for v in saved["region"]))
            channels = {name: saved[name] for name in CHANNELS if name in saved}
            return int(saved["index"]), PaintState(region, blank=bool(saved["blank"]), **channels)
    return None
