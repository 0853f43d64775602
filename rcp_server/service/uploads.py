"""Scenes that visitors upload: read in the sandbox (:mod:`rcp_server.untrusted`), kept apart from the
operator's under new unguessable names, within a count and a memory budget, and removed when nobody has
used them for a while.

Nothing lists them: whoever holds a name (and the token, when the server has one) can use it wherever a
scene name goes, which is what keeps one visitor's model from the others.
"""

from __future__ import annotations

import asyncio
import re
import secrets
import shutil
import tempfile
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..scene import Scene
from ..scenefile import model_scene
from ..untrusted import Limits, Refused, read_model
from . import protocol

NAME_PREFIX = "u-"  # then 22 characters of a 128-bit random token: a valid scene name, never a guessable one
BVH_BYTES_PER_TRIANGLE = 160  # Embree: its copy of the triangles and its tree (163 B measured on the staircase)


class Full(Exception):
    """No room for another uploaded scene; the message says which limit, ``retry_after`` when it frees itself."""

    def __init__(self, message: str, retry_after: int):
        super().__init__(message)
        self.retry_after = retry_after


@dataclass
class Upload:
    """One uploaded scene: its description, what it weighs in memory (bytes), when it was last used."""

    scene: Scene
    info: protocol.SceneInfo
    weight: int
    used: float  # time.monotonic()


@dataclass
class Uploads:
    """The uploaded scenes by name, and the gate that lets one upload be read at a time (two may wait)."""

    scenes: dict[str, Upload] = field(default_factory=dict)
    reading: asyncio.Semaphore = field(default_factory=lambda: asyncio.Semaphore(1))
    queued: int = 0  # uploads reading or waiting to

    @property
    def weight(self) -> int:
        return sum(upload.weight for upload in self.scenes.values())

    def get(self, name: str) -> Upload | None:
        """The upload called ``name``, marked as used now; None if there is none (or it was removed)."""
        upload = self.scenes.get(name)
        if upload is not None:
            upload.used = time.monotonic()
        return upload

    def remove(self, name: str) -> bool:
        return self.scenes.pop(name, None) is not None

    def sweep(self, idle_s: float, in_use: Iterable[Scene | None] = ()) -> list[str]:
        """Removes the uploads unused for ``idle_s`` seconds; a scene that a walk-through shows is in use."""
        now = time.monotonic()
        shown = {id(scene) for scene in in_use}
        for upload in self.scenes.values():
            if id(upload.scene) in shown:
                upload.used = now
        idle = [name for name, upload in self.scenes.items() if now - upload.used > idle_s]
        for name in idle:
            del self.scenes[name]
        return idle

    def check_room(self, max_scenes: int, idle_s: float) -> None:
        """Refuses (:class:`Full`) a new upload when ``max_scenes`` are kept already."""
        if len(self.scenes) >= max_scenes:
            oldest = min(upload.used for upload in self.scenes.values())
            raise Full(
                f"the server keeps at most {max_scenes} uploaded scenes and has them all; delete one of yours, "
                "or try again later",
                max(1, int(idle_s - (time.monotonic() - oldest)) + 1),
            )

    def add(self, scene: Scene, info: protocol.SceneInfo, weight: int, max_scenes: int, total_bytes: int) -> None:
        """Keeps ``scene`` under its name, or refuses (:class:`Full`) past the count or the memory budget."""
        self.check_room(max_scenes, 0)
        if self.weight + weight > total_bytes:
            raise Full(
                f"the scene needs {weight >> 20} MiB and the uploaded scenes may take {total_bytes >> 20} MiB "
                f"together, {self.weight >> 20} MiB of which are taken; try again later, or a smaller model",
                60,
            )
        self.scenes[scene.name] = Upload(scene, info, weight, time.monotonic())


def new_name() -> str:
    return NAME_PREFIX + secrets.token_urlsafe(16)


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


def read_scene(body: BinaryIO, filename: str, limits: Limits) -> tuple[Scene, int]:
    """Blocking (seconds: run it in a worker thread): the uploaded ``body`` as a new scene with a new name,
    and its weight in bytes. Raises :class:`Refused` with the reason."""
    work = Path(tempfile.mkdtemp(prefix="rcp-upload-"))
    try:
        with open(work / "upload", "wb") as sink:
            shutil.copyfileobj(body, sink, 1 << 20)
        model = read_model(work, filename, limits)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    scene = model_scene(model, new_name(), title_of(filename))  # builds its tree now, not on the first frame
    return scene, weight_of(scene)


__all__ = ["Full", "Refused", "Upload", "Uploads", "new_name", "read_scene", "title_of", "weight_of"]
