"""The data folder (``RCP_DATA``): what a server keeps across restarts, and the one module that writes it.

::

    RCP_DATA/
      lock             held (``flock``) by the one server using the folder, its pid inside
      rcp.sqlite       the records, in SQLite (WAL mode: a reader never waits for a writer)
      uploads/NAME/    an uploaded model: the file as it came (``original``) and its parsed arrays (``parts.npz``)
      videos/ID.mp4    a finished video
      videos/ID/       a video job's frames as they finish (``frame_000000.png``, lossless), and for a temporal
                       job the painting state the next frame continues from (``state.npz``)

The folder is untrusted input (anyone who could write it between two runs may have): every record is read
through a typed model whose names must be the ones this module makes (:data:`UPLOAD_NAME`, :data:`VIDEO_ID`),
and a row that does not fit is skipped with one log line naming the row and the folder; every path is made
from such a name inside the folder; nothing is written, deleted or served through a symbolic link (files are
opened with ``O_NOFOLLOW``, folders checked with ``lstat``); every stored file is read only if it is a regular
file of bounded size (a FIFO or a device would block a read forever).

Records hold wall-clock times (``time.time()``, seconds): they must mean the same after a restart. A record is
written after the files it describes, so a ``kill -9`` at any point leaves files without a record (removed at
the next start), never a record without its files.
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import re
import secrets
import shutil
import sqlite3
import stat
import threading
import zipfile
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path
from typing import Annotated, Any, BinaryIO, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..camera.camera import Region
from ..engine.paintstate import CHANNELS, PaintState
from ..media.camerapath import PathSpec
from ..scene.scenefile import SCENE_NAME, one_line

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


UPLOAD_NAME = re.compile(r"u-[A-Za-z0-9_-]{22}")  # "u-" and a 128-bit token, url-safe base64 (:func:`new_upload_name`)
VIDEO_ID = re.compile(r"[0-9a-f]{16}")  # a 64-bit token in hex (:func:`new_video_id`)
STATES = ("queued", "running", "done", "failed", "cancelled")
MAX_TEXT = 4096  # characters of a record's title or message


def new_upload_name() -> str:
    return "u-" + secrets.token_urlsafe(16)


def new_video_id() -> str:
    return secrets.token_hex(8)


class DataFolderError(RuntimeError):
    """The data folder cannot be used (another server holds it, or it cannot be written); one line, said at
    start-up."""


class UnsafeFile(OSError):
    """A stored file that is not a regular file of this folder (a symbolic link, a FIFO, a device, a folder),
    or larger than it may be; the message names the file inside the data folder only."""


Finite = Annotated[float, Field(allow_inf_nan=False)]
Count = Annotated[int, Field(ge=0, le=1 << 62)]


class _Record(BaseModel):
    model_config = ConfigDict(frozen=True, strict=True, extra="forbid")


class UploadRecord(_Record):
    name: Annotated[str, Field(pattern=f"^{UPLOAD_NAME.pattern}$")]
    title: Annotated[str, Field(max_length=MAX_TEXT)]
    owner: Annotated[str, Field(pattern="^[0-9a-f]{64}$")] | None  # sha256 of the token it came with
    file_bytes: Count
    weight: Count
    created: Finite
    used: Finite


class VideoSettings(BaseModel):
    """What a video job paints, as its record keeps it (``videos.VideoJob.settings``)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    path: PathSpec
    width: Annotated[int, Field(ge=1, le=1 << 16)]  # the painting's (both eyes of a stereo film)
    height: Annotated[int, Field(ge=1, le=1 << 16)]
    params: dict[str, Any]  # checked as PaintParams when the job is made
    temporal: Annotated[int, Field(ge=1, le=256)] | None


class VideoRecord(_Record):
    id: Annotated[str, Field(pattern=f"^{VIDEO_ID.pattern}$")]
    scene: Annotated[str, Field(pattern=f"^{SCENE_NAME.pattern}$")]
    settings: VideoSettings
    frames: Count
    state: Literal["queued", "running", "done", "failed", "cancelled"]
    done_frames: Count
    message: Annotated[str, Field(max_length=MAX_TEXT)]
    created: Finite
    finished: Finite | None
    bytes: Count


class Store:
    """The data folder of one server: holds its lock and its database connection (every thread shares both,
    one statement at a time). ``close`` lets go of the folder."""

    def __init__(self, folder: Path):
        self.folder = Path(folder).expanduser()
        self.uploads_dir = self.folder / "uploads"
        self.videos_dir = self.folder / "videos"
        try:
            self.folder.mkdir(parents=True, exist_ok=True)  # the operator's: it may be a link they made
            for path in (self.uploads_dir, self.videos_dir):
                real_dir(path)
        except OSError as exc:
            raise DataFolderError(f"cannot use the data folder {self.folder}: {exc.strerror or exc}") from None
        self._lock_file = _lock(self.folder / "lock")
        for name in ("rcp.sqlite", "rcp.sqlite-wal", "rcp.sqlite-shm", "rcp.sqlite-journal"):
            try:  # SQLite opens them by name: a link would be written through, a FIFO would block its first read
                mode = os.lstat(self.folder / name).st_mode
            except FileNotFoundError:
                continue
            if not stat.S_ISREG(mode):
                self._lock_file.close()
                raise DataFolderError(f"cannot use the records in {self.folder}: {name} is not a regular file")
        try:
            self._db = sqlite3.connect(self.folder / "rcp.sqlite", check_same_thread=False, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")  # WAL: a power cut may lose the last records, not corrupt
            self._db.executescript(SCHEMA)
        except sqlite3.Error as exc:
            self._lock_file.close()
            raise DataFolderError(f"cannot use the records in {self.folder / 'rcp.sqlite'}: {exc}") from None
        self._mutex = threading.Lock()
        self._skipped: set[tuple[str, int]] = set()  # the rows said to be skipped

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

    def _records(self, table: str, read: Callable[[dict], Any]) -> list:
        """The rows of ``table`` that ``read`` takes; each other row is skipped, said in one line with its row
        number and the folder (nothing of it is used: not its names, not its files)."""
        cursor = self._run(f"SELECT rowid, * FROM {table} ORDER BY created")
        with self._mutex:
            names = [d[0] for d in self._db.execute(f"SELECT * FROM {table} LIMIT 0").description]
        records = []
        for rowid, *values in cursor:
            try:
                records.append(read(dict(zip(names, values, strict=True))))
            except ValueError as exc:  # ValidationError among them; settings that are not JSON
                if (table, rowid) not in self._skipped:  # said once, however often the records are read
                    self._skipped.add((table, rowid))
                    reason = one_line(exc) if isinstance(exc, ValidationError) else str(exc)
                    log.warning("data folder %s: %s row %d skipped: %s", self.folder, table, rowid, reason)
        return records

    # ---- uploads ----

    def upload_dir(self, name: str) -> Path:
        return _inside(self.uploads_dir, name, UPLOAD_NAME)

    def add_upload(self, record: UploadRecord) -> None:
        """Records an upload whose files are in :meth:`upload_dir` already."""
        self._run(f"INSERT OR REPLACE INTO uploads VALUES ({_marks(UploadRecord)})", astuple(record))

    def uploads(self) -> list[UploadRecord]:
        return self._records("uploads", UploadRecord.model_validate)

    def touch_upload(self, name: str, used: float) -> None:
        self._run("UPDATE uploads SET used = ? WHERE name = ?", (used, name))

    def remove_upload(self, name: str) -> None:
        """The record first, then the files: a crash in between leaves files that the next start removes."""
        self._run("DELETE FROM uploads WHERE name = ?", (name,))
        remove(self.upload_dir(name))

    # ---- videos ----

    def video_file(self, video_id: str) -> Path:
        return _inside(self.videos_dir, video_id, VIDEO_ID, ".mp4")

    def frames_dir(self, video_id: str) -> Path:
        return _inside(self.videos_dir, video_id, VIDEO_ID)

    def add_video(self, record: VideoRecord) -> None:
        self._run(f"INSERT INTO videos VALUES ({_marks(VideoRecord)})", astuple(record))

    def update_video(self, video_id: str, **values) -> None:
        names = ", ".join(f"{name} = ?" for name in values)
        self._run(f"UPDATE videos SET {names} WHERE id = ?", (*values.values(), video_id))

    def videos(self) -> list[VideoRecord]:
        def read(row: dict) -> VideoRecord:
            if not isinstance(row["settings"], str):
                raise ValueError(f"its settings are {type(row['settings']).__name__}, not JSON text")
            try:
                settings = json.loads(row["settings"])
            except json.JSONDecodeError as exc:
                raise ValueError(f"its settings are not JSON ({exc.msg})") from None
            return VideoRecord.model_validate({**row, "settings": VideoSettings.model_validate(settings)})

        return self._records("videos", read)

    def remove_video(self, video_id: str) -> None:
        self._run("DELETE FROM videos WHERE id = ?", (video_id,))
        remove(self.video_file(video_id))
        remove(self.frames_dir(video_id))

    # ---- keeping house ----

    def remove_strays(self) -> None:
        """Files no record describes (a crash between writing them and recording them, or put there by someone
        else): removed, a symbolic link as a link (never what it points to)."""
        uploads = {record.name for record in self.uploads()}
        for path in self.uploads_dir.iterdir():
            if path.name not in uploads:
                remove(path)
        videos = {record.id for record in self.videos()}
        for path in self.videos_dir.iterdir():
            if path.name.split(".")[0] not in videos and path.name.lstrip(".").split(".")[0] not in videos:
                remove(path)


def astuple(record: _Record) -> tuple:
    values = record.model_dump()
    if isinstance(record, VideoRecord):
        values["settings"] = record.settings.model_dump_json()
    return tuple(values.values())


def _marks(record_type: type[_Record]) -> str:
    return ", ".join("?" for _ in record_type.model_fields)


def _inside(folder: Path, name: str, pattern: re.Pattern, suffix: str = "") -> Path:
    """``folder/name+suffix`` for a ``name`` this module makes; ``ValueError`` for any other (a record's name
    is never a path: ``../x`` and ``/x`` do not match)."""
    if not isinstance(name, str) or not pattern.fullmatch(name):
        raise ValueError(f"{name!r} is not a name the server makes")
    return folder / f"{name}{suffix}"


def remove(path: Path) -> None:
    """Deletes ``path``: a real folder with what it holds (``shutil.rmtree`` follows no link inside), anything
    else (a file, a symbolic link, a FIFO) as the entry itself."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    try:
        if stat.S_ISDIR(mode):
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    except OSError as exc:
        log.warning("cannot remove %s from the data folder: %s", path.name, exc.strerror or exc)


def real_dir(path: Path, make: bool = True) -> Path:
    """``path`` as a folder of its own (made if missing, with ``make``): :class:`UnsafeFile` if it is a symbolic
    link or anything but a folder, so that nothing is read or written through it."""
    try:
        if make:
            path.mkdir(exist_ok=True)
        mode = os.lstat(path).st_mode
    except FileExistsError:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        raise UnsafeFile(f"{path.name} is missing from the data folder") from None
    if not stat.S_ISDIR(mode):
        raise UnsafeFile(f"{path.name} in the data folder is not a folder of its own")
    return path


def open_regular(path: Path, max_bytes: int) -> BinaryIO:
    """``path`` opened for reading if it is a regular file (not a link: ``O_NOFOLLOW``; not a FIFO or a device:
    opened without blocking and checked before anything is read) of at most ``max_bytes``; else
    :class:`UnsafeFile`, or ``FileNotFoundError``."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise UnsafeFile(f"{path.name} in the data folder cannot be read ({exc.strerror})") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise UnsafeFile(f"{path.name} in the data folder is not a regular file")
        if info.st_size > max_bytes:
            raise UnsafeFile(f"{path.name} in the data folder is larger than {max_bytes:,} bytes")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def regular_size(path: Path) -> int | None:
    """The size of ``path`` if it is a regular file of its own (not a link), else None."""
    try:
        info = os.lstat(path)
    except OSError:
        return None
    return info.st_size if stat.S_ISREG(info.st_mode) else None


def load_npz(path: Path, max_bytes: int) -> dict[str, np.ndarray]:
    """The arrays of a stored ``.npz`` (:func:`open_regular`), never more than ``max_bytes`` unpacked; no
    pickles. :class:`UnsafeFile`, ``FileNotFoundError`` or ``ValueError`` for one that cannot be read."""
    with open_regular(path, max_bytes) as source:
        try:
            with zipfile.ZipFile(source) as archive:
                if sum(member.file_size for member in archive.infolist()) > max_bytes:
                    raise ValueError(f"{path.name}: its arrays unpack to more than {max_bytes:,} bytes")
            source.seek(0)
            with np.load(source, allow_pickle=False) as saved:
                return dict(saved.items())
        except (zipfile.BadZipFile, EOFError, KeyError, OSError) as exc:
            raise ValueError(f"{path.name}: not arrays ({type(exc).__name__})") from None


def _lock(path: Path):
    """The folder's lock, held for as long as the returned file is open; :class:`DataFolderError` if another
    process holds it (a lock the kernel drops with its holder: a ``kill -9`` leaves nothing stale), or if the
    lock is not a regular file of the folder (a symbolic link is never followed, so never truncated)."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        raise DataFolderError(f"cannot use the data folder {path.parent}: its lock: {exc.strerror}") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise DataFolderError(f"cannot use the data folder {path.parent}: its lock is not a regular file")
    os.set_blocking(fd, True)
    handle = os.fdopen(fd, "r+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.seek(0)
        holder = handle.read(32).strip() or "unknown"
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


def write_whole(path: Path, write: Callable[[BinaryIO], None]) -> None:
    """``write(sink)`` into a new temporary file beside ``path``, then the file moved into place: a reader (or a
    restart) sees it whole or not at all. Whatever had the temporary's name (a link among them) is removed
    first, and the temporary is created anew (``O_EXCL | O_NOFOLLOW``): nothing is written through a link."""
    partial = path.with_name(f".{path.name}.part")
    remove(partial)
    fd = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    with os.fdopen(fd, "wb") as sink:
        write(sink)
    os.replace(partial, path)


def save_state(path: Path, index: int, state: PaintState) -> None:
    """The painting state after frame ``index`` of a temporal video, whole (see :func:`write_whole`)."""
    arrays = {name: getattr(state, name) for name in CHANNELS if getattr(state, name) is not None}
    region = np.array([getattr(state.region, f.name) for f in fields(Region)], np.int64)

    def write(sink: BinaryIO) -> None:
        np.savez(sink, index=np.int64(index), region=region, blank=np.bool_(state.blank), **arrays)

    write_whole(path, write)


def load_state(path: Path, max_bytes: int) -> tuple[int, PaintState] | None:
    """The frame index and state :func:`save_state` wrote, None if there is none or it cannot be read (a
    damaged state, or one of more than ``max_bytes``, is painted again, not trusted)."""
    try:
        saved = load_npz(path, max_bytes)
        region = Region(*(int(v) for v in saved["region"]))
        channels = {name: saved[name] for name in CHANNELS if name in saved}
        return int(saved["index"]), PaintState(region, blank=bool(saved["blank"]), **channels)
    except (OSError, ValueError, KeyError, TypeError):
        return None
