"""Which object a pixel of a view shows, and where an object shows: what the walk's picks answer."""

from __future__ import annotations

import numpy as np

from ..camera.camera import Camera, Region
from ..engine import kernels
from ..scene.scene import Scene
from .seen import visible_faces


def pick(scene: Scene, time: float, camera: Camera, width: int, height: int, x: int, y: int) -> tuple[str, str] | None:
    """What pixel ``(x, y)`` of a ``width x height`` view by ``camera`` shows, at its centre: the names of its
    object and material ("" for a material with no name), or None for the sky (one ray, traced here)."""
    if not (0 <= x < width and 0 <= y < height):
        raise ValueError(f"pixel ({x}, {y}) is not in a {width}x{height} view")
    seen = kernels.Seen.empty(1, 1)
    visible_faces(scene, time, camera, Region(width, height, x, y, 1, 1), seen)
    face = int(seen.face[0])
    if face < 0:
        return None
    geometry, _ = scene.geometry(time)
    return geometry.object_names[geometry.face_object[face]], geometry.material_names[geometry.face_material[face]]


def object_pixels(scene: Scene, time: float, camera: Camera, width: int, height: int, name: str) -> np.ndarray:
    """Which pixel centres of a ``width x height`` view by ``camera`` show the object called ``name`` (what
    :func:`pick` answers): (height, width) bool, row-major, top row first."""
    seen = kernels.Seen.empty(width, height)
    visible_faces(scene, time, camera, Region(width, height), seen)
    geometry, _ = scene.geometry(time)
    if name not in geometry.object_names:
        return np.zeros((height, width), bool)
    hit = seen.face >= 0
    shows = np.zeros(width * height, bool)
    shows[hit] = geometry.face_object[seen.face[hit]] == geometry.object_names.index(name)
    return shows.reshape(height, width)
