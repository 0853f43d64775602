"""A scene at a point in time: world-space triangles with their shading data, an environment, a light.

``S(n)`` of the paper is :meth:`Scene.geometry` at a time: objects may spin and bob, and a mesh may be
deformed by waves. A static scene builds its geometry once; a scene with no mesh builds none at all.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..camera.camera import Camera
from ..engine.kernels.embree import Tracer
from ..settings.params import PaintParams
from ..settings.styles import with_style
from .meshes import PLAIN, Material, Part, corner_normals, rgb8
from .motion import CameraMotion


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
    label: str = ""  # what paintings call it (per-object settings; the parts of one mesh share it): "" its name

    @property
    def called(self) -> str:
        return self.label or self.name

    @property
    def animated(self) -> bool:
        return self.motion is not None or bool(self.waves)


@dataclass
class Geometry:
    """Every triangle of the scene at one time, in world space.

    triangles : (F, 3, 3) float32;  normals : (F, 3, 3) float32, unit shading normals per corner
    colors : (F, 3, 3) float32 albedo per corner;  uv : (F, 3, 2) float32;  texture_id : (F,) int32, -1 none
    textures : packed texels (T, 3) uint8 RGB display colors with (K,) offsets, widths and heights (int64);
    the coverage of those that let rays through, packed apart: alpha_texels (A,) uint8 and
    texture_alpha_offset (K,) int64, -1 for a texture without
    materials (``meshes.Material``, one row per distinct one): face_material (F,) int32 its row;
    material_emission (M, 3) float32 display color added after light; material_emission_texture (M,)
    int32 texture or -1; material_unlit (M,) bool; material_alpha_cutoff (M,) float32, 0 when opaque
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
    alpha_texels: np.ndarray = field(default_factory=lambda: np.zeros(1, np.uint8))
    texture_alpha_offset: np.ndarray = field(default_factory=lambda: np.full(1, -1, np.int64))
    face_material: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    material_emission: np.ndarray = field(default_factory=lambda: np.zeros((1, 3), np.float32))
    material_emission_texture: np.ndarray = field(default_factory=lambda: np.full(1, -1, np.int32))
    material_unlit: np.ndarray = field(default_factory=lambda: np.zeros(1, np.bool_))
    material_alpha_cutoff: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    material_bands: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int32))
    material_outline: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    material_names: list[str] = field(default_factory=lambda: [""])
    face_object: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    object_names: list[str] = field(default_factory=list)
    bounds: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))  # (2, 3) min and max corner

    @property
    def face_count(self) -> int:
        return len(self.triangles)

    @property
    def masked(self) -> bool:
        """Some surface has texels that rays pass through (``kernels.alpha``); without, nothing is checked."""
        return bool((self.material_alpha_cutoff > 0).any())


def object_names(objects: list[SceneObject]) -> list[str]:
    """The objects a painting can tell apart, by name, in order: the index the object channel records."""
    return list(dict.fromkeys(obj.called for obj in objects))


def material_names(objects: list[SceneObject]) -> list[str]:
    """The named materials of the objects' parts, each once, in order."""
    names = (part.material.name for obj in objects for _, part in obj.instances)
    return [name for name in dict.fromkeys(names) if name]


def _transform_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ m[:3, :3].T + m[:3, 3]


def _placed(obj: SceneObject, time: float) -> list[tuple[np.ndarray, np.ndarray, Part]]:
    """World triangles (F, 3, 3) and unit corner normals (F, 3, 3) of each instance of ``obj`` at ``time``,
    float32 (what the tracer and the shading read)."""
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
        placed.append((tri.astype(np.float32), n.astype(np.float32), part))
    return placed


class _Packer:
    """Distinct textures and materials of a scene, each once, in the order first met."""

    def __init__(self):
        self.textures: dict[int, tuple[int, np.ndarray]] = {}  # id(texture array) -> (index, 8-bit RGB array)
        self.materials: dict[int, tuple[int, Material]] = {}
        self.alphas: dict[int, np.ndarray] = {}  # texture index -> its coverage (h, w) uint8

    def texture(self, image: np.ndarray | None) -> int:
        if image is None:
            return -1
        if id(image) not in self.textures:
            self.textures[id(image)] = (len(self.textures), rgb8(image))
        return self.textures[id(image)][0]

    def alpha(self, texture: int, alpha: np.ndarray | None) -> None:
        if texture >= 0 and alpha is not None:
            self.alphas.setdefault(texture, alpha)

    def packed_alphas(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """(A,) uint8 coverage of every texture that has one, and (count,) int64 where each starts (-1 none)."""
        offsets = np.full(max(count, 1), -1, np.int64)
        chunks, start = [], 0
        for k, alpha in sorted(self.alphas.items()):
            offsets[k] = start
            chunks.append(alpha.reshape(-1))
            start += alpha.size
        return (np.concatenate(chunks) if chunks else np.zeros(1, np.uint8)), offsets

    def material(self, material: Material) -> int:
        if id(material) not in self.materials:
            self.texture(material.emission_texture)
            self.materials[id(material)] = (len(self.materials), material)
        return self.materials[id(material)][0]


def _store_of(images: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    """The texels of ``images`` ((h, w, 3) uint8 each) packed as (T, 3) with each one's first texel: the
    store they are all views of (``meshes.packed``), taken as it is, or else a new one."""
    if not images:
        return None
    base = images[0].base
    while isinstance(base, np.ndarray) and base.base is not None and isinstance(base.base, np.ndarray):
        base = base.base
    if isinstance(base, np.ndarray) and base.ndim == 2 and base.shape[1] == 3 and base.dtype == np.uint8:
        start = base.__array_interface__["data"][0]
        offsets = []
        for im in images:
            delta = im.__array_interface__["data"][0] - start
            inside = 0 <= delta and delta + im.nbytes <= base.nbytes and im.flags.c_contiguous
            if not (inside and np.may_share_memory(im, base)):
                break
            offsets.append(delta // 3)
        else:
            return base, np.asarray(offsets, np.int64)
    sizes = np.array([im.shape[0] * im.shape[1] for im in images], dtype=np.int64)
    texels = np.concatenate([im.reshape(-1, 3) for im in images], dtype=np.uint8)
    return texels, np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)


def build_geometry(objects: list[SceneObject], time: float, static_cache: dict | None = None) -> Geometry:
    """Concatenate all instances of all objects, placed and deformed at ``time``.

    ``static_cache`` keeps the placed instances of objects that do not move, so an animated scene
    re-places only what moves. Each array is made once, in the dtype it keeps (the staircase interior's
    geometry is 262k triangles: a copy of each array is tens of MB).
    """
    tris, normals, colors, uvs, tex_ids, face_materials, face_objects = [], [], [], [], [], [], []
    names = object_names(objects)
    packer = _Packer()
    packer.material(PLAIN)  # row 0: every part without a material of its own
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
            index = packer.texture(part.texture)
            packer.alpha(index, part.material.alpha_texture)
            row = 0 if part.material.plain else packer.material(part.material)
            corner_uv = part.corner_uv  # kept untextured too: the uv channel reads them
            uvs.append(corner_uv if corner_uv is not None else np.zeros((len(tri), 3, 2), np.float32))
            tex_ids.append(np.full(len(tri), index, np.int32))
            face_materials.append(np.full(len(tri), row, np.int32))
            face_objects.append(np.full(len(tri), names.index(obj.called), np.int32))
    images = [image for _, image in sorted(packer.textures.values(), key=lambda item: item[0])]
    store = _store_of(images)
    materials = [m for _, m in sorted(packer.materials.values(), key=lambda item: item[0])]
    alpha_texels, alpha_offsets = packer.packed_alphas(len(images))
    triangles = np.concatenate(tris, dtype=np.float32) if tris else np.zeros((0, 3, 3), np.float32)
    points = triangles.reshape(-1, 3) if tris else np.zeros((1, 3), np.float32)
    return Geometry(
        triangles=triangles,
        normals=np.concatenate(normals, dtype=np.float32) if normals else np.zeros((0, 3, 3), np.float32),
        colors=np.concatenate(colors, dtype=np.float32) if colors else np.zeros((0, 3, 3), np.float32),
        uv=np.concatenate(uvs, dtype=np.float32) if uvs else np.zeros((0, 3, 2), np.float32),
        texture_id=np.concatenate(tex_ids) if tex_ids else np.zeros(0, np.int32),
        texels=store[0] if store else np.zeros((1, 3), np.uint8),
        texture_offset=store[1] if store else np.zeros(1, np.int64),
        texture_width=np.array([im.shape[1] for im in images] or [1], dtype=np.int64),
        texture_height=np.array([im.shape[0] for im in images] or [1], dtype=np.int64),
        alpha_texels=alpha_texels,
        texture_alpha_offset=alpha_offsets,
        face_material=np.concatenate(face_materials) if face_materials else np.zeros(0, np.int32),
        material_emission=np.array([m.emission for m in materials], dtype=np.float32).reshape(-1, 3),
        material_emission_texture=np.array([packer.texture(m.emission_texture) for m in materials], dtype=np.int32),
        material_unlit=np.array([m.unlit for m in materials], dtype=np.bool_),
        material_alpha_cutoff=np.array([m.alpha_cutoff for m in materials], dtype=np.float32),
        material_bands=np.array([m.bands for m in materials], dtype=np.int32),
        material_outline=np.array([m.outline for m in materials], dtype=np.float32),
        material_names=[m.name for m in materials],
        face_object=np.concatenate(face_objects) if face_objects else np.zeros(0, np.int32),
        object_names=names,
        bounds=np.stack([points.min(axis=0), points.max(axis=0)]).astype(np.float64),
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
    viewpoints: dict[str, Camera] = field(default_factory=dict)  # other cameras offered by name (a glTF's)
    motions: dict[str, CameraMotion] = field(default_factory=dict)  # animated cameras by name (a glTF's)
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
                geometry = build_geometry(self.objects, key, self._static if self.animated else None)
                tracer = Tracer(geometry.triangles) if geometry.face_count else None
                while len(self._cache) >= 4:
                    self._cache.pop(next(iter(self._cache)))
                self._cache[key] = (geometry, tracer)
            return self._cache[key]

    def painting(self, settings: Mapping[str, Any]) -> PaintParams:
        """This scene's painting with ``settings`` (``styles.with_style``: a style, then settings by name, the
        overrides per object and per material merged into the scene's); ``ValueError`` in one line for a
        setting it cannot take or an object or material this scene does not have."""
        params = with_style(self.paint, settings)
        self.check_names(params)
        return params

    def check_names(self, params: PaintParams) -> None:
        """``ValueError`` (one line, with the names it has) unless the objects and materials that ``params``
        sets apart are this scene's."""
        for per, names in (("objects", object_names(self.objects)), ("materials", material_names(self.objects))):
            unknown = [name for name, _ in getattr(params, per) if name not in names]
            if unknown:
                have = ", ".join(repr(n) for n in names[:12]) + (" ..." if len(names) > 12 else "") or "none"
                raise ValueError(f"{per}: this scene has no {', '.join(map(repr, unknown))} (it has: {have})")

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
