"""A scene at a point in time: world-space triangles with their shading data, an environment, a light.

``S(n)`` of the paper is :meth:`Scene.geometry` at a time: objects may spin and bob, and a mesh may be
deformed by waves. A static scene builds its geometry once; a scene with no mesh builds none at all.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .meshes import Part, corner_normals
from .params import PaintParams
from .tracer import Tracer


@dataclass(frozen=True)
class Environment:
    """What a missed ray sees: an equirectangular image on an infinite sphere, (h, w, 3) float32.

    A constant color is a 1x1 image. Longitude 0 looks along -z, +x is a quarter turn right; the
    image's top row is straight up.
    """

    image: np.ndarray

    @classmethod
    def constant(cls, color) -> Environment:
        return cls(np.asarray(color, dtype=np.float32).reshape(1, 1, 3))


@dataclass(frozen=True)
class Light:
    """One directional light plus ambient: ``albedo * (ambient + (1 - ambient) * max(0, n . -direction))``."""

    direction: tuple[float, float, float]  # the way the light travels, unit length
    ambient: float = 0.3


@dataclass(frozen=True)
class Waves:
    """Sum of travelling sine waves lifting a mesh along its local +y (the paper's sea)."""

    amplitude: float
    wavelength: float
    direction: tuple[float, float]  # in the local xz plane
    speed: float  # scene units per second

    def height(self, x: np.ndarray, z: np.ndarray, time: float) -> np.ndarray:
        d = np.asarray(self.direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        k = 2.0 * math.pi / self.wavelength
        return self.amplitude * np.sin(k * (x * d[0] + z * d[1] - self.speed * time))


@dataclass
class SceneObject:
    """A part placed in the world in one or more instances; it may move: ``motion(time)`` (4x4 float64,
    applied in object space before each instance's placement) and ``waves`` deforming its vertices."""

    name: str
    part: Part
    instances: list[tuple[np.ndarray, Part]]  # (world_from_object at time 0, the part as tinted there)
    motion: Callable[[float], np.ndarray] | None = None  # world_from_object change at a time, 4x4
    waves: tuple[Waves, ...] = ()

    @property
    def animated(self) -> bool:
        return self.motion is not None or bool(self.waves)


@dataclass
class Geometry:
    """Every triangle of the scene at one time, in world space.

    triangles : (F, 3, 3) float32;  normals : (F, 3, 3) float32, unit shading normals per corner
    colors : (F, 3, 3) float32 albedo per corner;  uv : (F, 3, 2) float32;  texture_id : (F,) int32, -1 none
    textures : packed texels (T, 3) float32 with (K,) offsets, widths and heights (int64)
    """

    triangles: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    uv: np.ndarray
    texture_id: np.ndarray
    texels: np.ndarray
    texture_offset: np.ndarray
    texture_width: np.ndarray
    texture_height: np.ndarray
    bounds: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))  # (2, 3) min and max corner

    @property
    def face_count(self) -> int:
        return len(self.triangles)


def _transform_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ m[:3, :3].T + m[:3, 3]


def _placed(obj: SceneObject, time: float) -> list[tuple[np.ndarray, np.ndarray, Part]]:
    """World triangles (F, 3, 3) and unit corner normals (F, 3, 3) of each instance of ``obj`` at ``time``."""
    vertices = obj.part.vertices
    if obj.waves:
        vertices = vertices.copy()
        for w in obj.waves:
            vertices[:, 1] += w.height(vertices[:, 0], vertices[:, 2], time)
    local_normals = corner_normals(vertices, obj.part.faces)
    motion = obj.motion(time) if obj.motion is not None else np.eye(4)
    placed = []
    for world_from_object, part in obj.instances:
        m = world_from_object @ motion
        tri = _transform_points(m, vertices[part.faces].reshape(-1, 3)).reshape(-1, 3, 3)
        n = (local_normals.reshape(-1, 3) @ np.linalg.inv(m[:3, :3])).reshape(-1, 3, 3)  # inverse transpose
        n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-30)
        if np.linalg.det(m[:3, :3]) < 0:  # a mirroring transform flips the winding; keep normals outward
            n = -n
        placed.append((tri, n, part))
    return placed


def build_geometry(objects: list[SceneObject], time: float, static_cache: dict | None = None) -> Geometry:
    """Concatenate all instances of all objects, placed and deformed at ``time``.

    ``static_cache`` keeps the placed instances of objects that do not move, so an animated scene
    re-places only what moves.
    """
    tris, normals, colors, uvs, tex_ids = [], [], [], [], []
    textures: dict[int, tuple[int, np.ndarray]] = {}  # id(texture array) -> (index, array)
    for obj in objects:
        if obj.animated or static_cache is None:
            placed = _placed(obj, time)
        else:
            if id(obj) not in static_cache:
                static_cache[id(obj)] = _placed(obj, time)
            placed = static_cache[id(obj)]
        for tri, n, part in placed:
            tris.append(tri)
            normals.append(n)
            colors.append(part.corner_colors)
            if part.texture is not None and part.corner_uv is not None:  # a textured part has both
                index, _ = textures.setdefault(id(part.texture), (len(textures), part.texture))
                uvs.append(part.corner_uv)
                tex_ids.append(np.full(len(tri), index, np.int32))
            else:
                uvs.append(np.zeros((len(tri), 3, 2), np.float32))
                tex_ids.append(np.full(len(tri), -1, np.int32))
    images = [image for _, image in sorted(textures.values(), key=lambda item: item[0])]
    points = np.concatenate(tris).reshape(-1, 3) if tris else np.zeros((1, 3))
    sizes = np.array([im.shape[0] * im.shape[1] for im in images], dtype=np.int64)
    return Geometry(
        triangles=np.concatenate(tris).astype(np.float32) if tris else np.zeros((0, 3, 3), np.float32),
        normals=np.concatenate(normals).astype(np.float32) if normals else np.zeros((0, 3, 3), np.float32),
        colors=np.concatenate(colors).astype(np.float32) if colors else np.zeros((0, 3, 3), np.float32),
        uv=np.concatenate(uvs).astype(np.float32) if uvs else np.zeros((0, 3, 2), np.float32),
        texture_id=np.concatenate(tex_ids) if tex_ids else np.zeros(0, np.int32),
        texels=(
            np.concatenate([im.reshape(-1, 3) for im in images]).astype(np.float32)
            if images
            else np.zeros((1, 3), np.float32)
        ),
        texture_offset=np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        if images
        else np.zeros(1, np.int64),
        texture_width=np.array([im.shape[1] for im in images] or [1], dtype=np.int64),
        texture_height=np.array([im.shape[0] for im in images] or [1], dtype=np.int64),
        bounds=np.stack([points.min(axis=0), points.max(axis=0)]),
    )


@dataclass
class Scene:
    """A named scene: objects, environment, optional light, default camera and painting defaults."""

    name: str
    title: str
    camera: Camera
    environment: Environment
    light: Light | None = None
    objects: list[SceneObject] = field(default_factory=list)
    paint: PaintParams = field(default_factory=PaintParams)  # how this scene is painted unless told otherwise
    z_max: float | None = None  # depth a miss records; derived from the scene's size when None
    _cache: dict = field(default_factory=dict, repr=False)
    _static: dict = field(default_factory=dict, repr=False)  # placed instances of objects that never move
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    @property
    def animated(self) -> bool:
        return any(obj.animated for obj in self.objects)

    def geometry(self, time: float = 0.0) -> tuple[Geometry, Tracer | None]:
        """The geometry at ``time`` and its ray tracer (None when the scene has no triangles).

        Cached: once for a static scene, per time (the newest few) for an animated one.
        """
        key = float(time) if self.animated else 0.0
        with self._lock:
            if key not in self._cache:
                geometry = build_geometry(self.objects, key, self._static)
                tracer = Tracer(geometry.triangles) if geometry.face_count else None
                while len(self._cache) >= 4:
                    self._cache.pop(next(iter(self._cache)))
                self._cache[key] = (geometry, tracer)
            return self._cache[key]

    def depth_of_miss(self, eye, time: float = 0.0) -> float:
        """``z_max``: the depth recorded where a ray sees only the environment, seen from ``eye``.

        The scene file's ``z_max`` when it sets one; otherwise beyond the farthest point of the scene.
        """
        if self.z_max is not None:
            return self.z_max
        geometry, _ = self.geometry(time)
        if geometry.face_count == 0:
            return 100.0
        lo, hi = geometry.bounds
        return max(float(np.linalg.norm(hi - lo) + np.linalg.norm((lo + hi) / 2 - np.asarray(eye))), 1.0)
