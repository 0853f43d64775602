"""Scenes that visitors upload: read in the sandbox (:mod:`rcp_server.scene.untrusted`), kept apart from the
operator's under new unguessable names, within a count and a memory budget, and removed when nobody has
used them for a while.

Nothing lists them: whoever holds a name (and the token, when the server has one) can use it wherever a
scene name goes, which is what keeps one visitor's model from the others.
"""

from __future__ import annotations

import asyncio
import hashlib
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..scene.meshes import Model
from ..scene.scene import Scene
from ..scene.scenefile import SceneError, model_scene
from ..scene.untrusted import Limits, NoRoom, Refused, model_of_arrays, read_model
from . import protocol
from .refusal import Refusal
from .store import Store, UnsafeFile, UploadRecord, load_npz, new_upload_name, real_dir, regular_size

RECORD_USE_S = 60.0  # an upload's last use is written to the store at most this often (idle expiry is in minutes)
BVH_BYTES_PER_TRIANGLE = 160  # Embree: its copy of the triangles and its tree (163 B measured on the staircase)
MEMORY_RETRY_S = 60  # a caller turned away for the uploads' memory: scenes expire, or are deleted, in minutes


def full(message: str, retry_after: int) -> Refusal:
    """No room for another uploaded scene (503): the message says which limit, ``retry_after`` when it frees
    itself."""
    return Refusal(message, 503, retry_after)


def read_refusal(exc: Refused) -> Refusal:
    """What the reader's refusal of a file answers: 503 when what it declares would not fit in the memory left
    (:class:`NoRoom`: refused before it is built), else 422."""
    return Refusal(str(exc), 503, MEMORY_RETRY_S) if isinstance(exc, NoRoom) else Refusal(str(exc))


@dataclass
class Upload:
    """One uploaded scene: its description, what it weighs in memory (bytes), when it was last used."""

    scene: Scene
    info: protocol.SceneInfo
    weight: int
    used: float  # time.time(): it means the same after a restart
    recorded: float = 0.0  # the ``used`` the store holds (written at most every RECORD_USE_S)


@dataclass
class Uploads:
    """The uploaded scenes by name, and the gate that lets one upload be read at a time (two may wait)."""

    scenes: dict[str, Upload] = field(default_factory=dict)
    reading: asyncio.Semaphore = field(default_factory=lambda: asyncio.Semaphore(1))
    queued: int = 0  # uploads reading or waiting to
    store: Store | None = None  # where they are kept across restarts (None: in memory only)

    @property
    def weight(self) -> int:
        return sum(upload.weight for upload in self.scenes.values())

    def get(self, name: str) -> Upload | None:
        """The upload called ``name``, marked as used now; None if there is none (or it was removed)."""
        upload = self.scenes.get(name)
        if upload is not None:
            self._use(upload, time.time())
        return upload

    def _use(self, upload: Upload, now: float) -> None:
        upload.used = now
        if self.store is not None and now - upload.recorded > RECORD_USE_S:
            upload.recorded = now
            self.store.touch_upload(upload.scene.name, now)

    def flush(self) -> None:
        """Writes every last use the store does not hold yet (a clean stop loses none; a crash, at most
        ``RECORD_USE_S`` of them)."""
        for upload in self.scenes.values():
            if self.store is not None and upload.used != upload.recorded:
                upload.recorded = upload.used
                self.store.touch_upload(upload.scene.name, upload.used)

    def remove(self, name: str) -> bool:
        if self.scenes.pop(name, None) is None:
            return False
        if self.store is not None:
            self.store.remove_upload(name)
        return True

    def sweep(self, idle_s: float, in_use: Iterable[Scene | None] = ()) -> list[str]:
        """Removes the uploads unused for ``idle_s`` seconds; a scene that a walk-through shows is in use."""
        now = time.time()
        shown = {id(scene) for scene in in_use}
        for upload in self.scenes.values():
            if id(upload.scene) in shown:
                self._use(upload, now)
        idle = [name for name, upload in self.scenes.items() if now - upload.used > idle_s]
        for name in idle:
            self.remove(name)
        return idle

    def check_room(self, max_scenes: int, idle_s: float) -> None:
        """Refuses (:class:`~.refusal.Refusal` 503) a new upload when ``max_scenes`` are kept already."""
        if len(self.scenes) >= max_scenes:
            oldest = min(upload.used for upload in self.scenes.values())
            raise full(
                f"the server keeps at most {max_scenes} uploaded scenes and has them all; delete one of yours, "
                "or try again later",
                max(1, int(idle_s - (time.time() - oldest)) + 1),
            )

    def add(
        self,
        scene: Scene,
        info: protocol.SceneInfo,
        weight: int,
        max_scenes: int,
        total_bytes: int,
        owner: str | None = None,
    ) -> None:
        """Keeps ``scene`` under its name (recorded in the store, whose folder holds its files already), or
        refuses (:class:`~.refusal.Refusal` 503) past the count or the memory budget.
        ``owner``: the token it came with."""
        self.check_room(max_scenes, 0)
        if self.weight + weight > total_bytes:
            raise full(
                f"the scene needs {weight >> 20} MiB and the uploaded scenes may take {total_bytes >> 20} MiB "
                f"together, {self.weight >> 20} MiB of which are taken; try again later, or a smaller model",
                MEMORY_RETRY_S,
            )
        now = time.time()
        if self.store is not None:
            folder = self.store.upload_dir(scene.name)
            size = sum(regular_size(f) or 0 for f in folder.iterdir()) if folder.is_dir() else 0
            owned = None if owner is None else hashlib.sha256(owner.encode()).hexdigest()
            record = UploadRecord(
                name=scene.name, title=scene.title, owner=owned, file_bytes=size, weight=weight, created=now, used=now
            )
            self.store.add_upload(record)
        self.scenes[scene.name] = Upload(scene, info, weight, now, now)

    def keep(self, scene: Scene, info: protocol.SceneInfo, record: UploadRecord) -> None:
        """An upload the store held already (at start-up): kept as it was, last used when it was."""
        self.scenes[scene.name] = Upload(scene, info, record.weight, record.used, record.used)


def new_name() -> str:
    """A new upload's name: a valid scene name, never a guessable one (``store.UPLOAD_NAME``)."""
    return new_upload_name()


def title_of(filename: str) -> str:
    """A scene's title from the uploaded file's name: its stem, printable, at most 80 characters."""
    stem = Path(filename.replace("\\", "/")).stem
    return re.sub(r"\s+", " ", "".join(c if c.isprintable() else " " for c in stem)).strip()[:80] or "upload"


def weight_of(scene: Scene) -> int:
    """Bytes an uploaded scene holds: its parts, its traced geometry and (roughly) Embree's tree over it;
    an array that views another (a part's texture in the scene's one texture store) counts once, as that one."""
    geometry, _ = scene.geometry(0.0)
    arrays: dict[int, np.ndarray] = {}

    def count(a) -> None:
        if isinstance(a, np.ndarray):
            while isinstance(a.base, np.ndarray):
                a = a.base
            arrays[id(a)] = a

    for a in vars(geometry).values():
        count(a)
    for obj in scene.objects:
        for part in [obj.part, *(p for _, p in obj.instances)]:
            for a in (
                part.vertices,
                part.faces,
                part.corner_colors,
                part.corner_uv,
                part.texture,
                part.material.emission_texture,
                part.material.alpha_texture,
            ):
                count(a)
    return sum(a.nbytes for a in arrays.values()) + BVH_BYTES_PER_TRIANGLE * geometry.face_count


def read_scene(body: BinaryIO, filename: str, limits: Limits, keep: Path | None = None) -> tuple[Scene, int]:
    """Blocking (seconds: run it in a worker thread): the uploaded ``body`` as a new scene with a new name,
    and its weight in bytes. Raises :class:`Refused` with the reason. With ``keep`` (the store's uploads
    folder), the file and its parsed arrays stay in ``keep/NAME/`` (``original``, ``parts.npz``), for
    :func:`stored_scene` to load after a restart; the caller removes that folder if it does not keep the scene."""
    work = Path(tempfile.mkdtemp(prefix=".reading-", dir=keep))  # in ``keep``: moved into place by a rename
    try:
        with open(work / "upload", "wb") as sink:
            shutil.copyfileobj(body, sink, 1 << 20)
        name = new_name()
        scene = scene_of(read_model(work, filename, limits), name, title_of(filename))
        if keep is not None:
            folder = keep / name
            folder.mkdir()
            os.replace(work / "upload", folder / "original")
            os.replace(work / "parts.npz", folder / "parts.npz")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return scene, weight_of(scene)


def stored_scene(folder: Path, name: str, title: str, limits: Limits, max_bytes: int) -> Scene:
    """The scene of the parsed arrays in ``folder/parts.npz``, its tree built: the one path of a first upload
    and of a reload after a restart, so that both paint the same. The folder is the data folder's: read only
    if it and the file are what they should be (no link, no FIFO) and the arrays at most ``max_bytes``.
    Raises :class:`Refused`."""
    try:
        arrays = load_npz(real_dir(folder, make=False) / "parts.npz", max_bytes)
    except UnsafeFile as exc:
        raise Refused(str(exc)) from None
    except (OSError, ValueError) as exc:
        raise Refused(f"its arrays cannot be read ({type(exc).__name__})") from None
    return scene_of(model_of_arrays(arrays, limits), name, title)


def scene_of(model: Model, name: str, title: str) -> Scene:
    """A model as read from the sandbox's arrays (:func:`~rcp_server.scene.untrusted.parts_from_arrays`) as a scene
    as its authors made it (``scenefile.model_scene``), its tree built now rather than on the first frame.
    Raises :class:`Refused` for a model no camera can frame."""
    try:
        return model_scene(model, name, title)  # builds its tree (the framing reads it)
    except SceneError as exc:  # a model no camera can frame (far from the origin, or too large)
        raise Refused(str(exc)) from None


__all__ = [
    "MEMORY_RETRY_S",
    "full",
    "read_refusal",
    "NoRoom",
    "Refused",
    "Upload",
    "Uploads",
    "new_name",
    "read_scene",
    "stored_scene",
    "title_of",
    "weight_of",
]
