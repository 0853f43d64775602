"""Triangle meshes with their surface colors: loaded from files through trimesh, or built as primitives.

Every mesh becomes a :class:`Part`: vertices and faces plus per-corner shading data (colors, UVs, one
optional texture) and its :class:`Material` (emission, unlit, alpha mask), whatever the source carried: a
texture through UVs, vertex colors, face colors, or a flat color. A glTF also brings its cameras and lights
(:class:`Model`, read by ``gltf.py``). Textures stay 8-bit as the file holds them: RGB display colors,
and an alpha channel apart, kept only for a material that lets rays through its texels. Broken input is
repaired with a warning (non-finite vertices, zero-area faces) or refused with a :class:`MeshError` naming
the file.
"""

from __future__ import annotations

import gc
import logging
import math
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from . import gltf
from .motion import CameraMotion

log = logging.getLogger("rcp")

DEFAULT_ALBEDO = (0.8, 0.8, 0.8)
# two faces around a vertex shade as one surface when their normals lie within this angle, and as a crease
# otherwise. 48 degrees: above the 45 between the sides of an octagonal trunk and the at most 42 between
# two faces around a vertex of the coarsest shipped sphere (icosphere 1), so both stay round; below the 52
# between the sides of a four-sided pyramid roof and the 90 of a box, so those stay flat
CREASE_DEGREES = 48.0
CREASE_COS = math.cos(math.radians(CREASE_DEGREES))
# a vertex whose faces all lie within half the crease angle of their mean has no crease pair (the angle
# between two faces is at most the sum of their angles to the mean), so its corners take that mean
# without the pairwise test: all of the sea, every frame
_HALF_CREASE_COS = math.cos(math.radians(CREASE_DEGREES / 2))


class MeshError(ValueError):
    """A mesh that cannot be used; the message names the source and what is wrong."""


@dataclass(frozen=True, eq=False)
class Material:
    """What a surface shows beside its albedo.

    emission : display color added after lighting (glTF's emissiveFactor), times ``emission_texture``
    ((h, w, 3) uint8 over the part's UVs) when there is one;  unlit : the albedo as it is, no light
    alpha_texture : (h, w) uint8 coverage over the part's UVs, the size of the part's texture, or None;
    alpha_cutoff : a hit where it (in [0, 1]) is below this lets the ray through (glTF's MASK; BLEND is
    drawn as a mask at 0.5; OBJ's map_d); 0: opaque
    name : what paintings call it (per-material settings); ""  has none
    bands : toon shading, the light in this many flat bands (``kernels.shade``); 0: smooth
    outline : how dark the ink where the object, the surface normal or the depth jumps (``outlines.py``); 0 none
    """

    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    emission_texture: np.ndarray | None = None
    unlit: bool = False
    alpha_cutoff: float = 0.0
    alpha_texture: np.ndarray | None = None
    name: str = ""
    bands: int = 0
    outline: float = 0.0

    @property
    def plain(self) -> bool:
        return (
            self.emission_texture is None
            and not any(self.emission)
            and not self.unlit
            and not self.alpha_cutoff
            and not self.name
            and not self.bands
            and not self.outline
        )


PLAIN = Material()


@dataclass
class Part:
    """One surface in object space.

    vertices : (V, 3) float64, scene units;  faces : (F, 3) int64
    corner_colors : (F, 3, 3) float32, display colors in [0, 1], multiplied into the texture when there is one
    corner_uv : (F, 3, 2) float32 or None;  texture : (h, w, 3) uint8 RGB display colors (as the file holds
    them) or None
    colored : the source carried colors of its own (a texture or material color, vertex or face colors);
    otherwise corner_colors is the default grey
    """

    vertices: np.ndarray
    faces: np.ndarray
    corner_colors: np.ndarray
    corner_uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    colored: bool = False
    material: Material = PLAIN

    def tinted(self, color) -> Part:
        return replace(self, corner_colors=self.corner_colors * np.asarray(color, np.float32).reshape(1, 1, 3))


def _grey(face_count: int) -> np.ndarray:
    return np.broadcast_to(np.float32(DEFAULT_ALBEDO), (face_count, 3, 3)).copy()


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (..., 3) arrays: (...)."""
    return np.einsum("...k,...k->...", a, b)


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length: (..., 3); a zero row stays zero."""
    length = np.sqrt(_dot(v, v))[..., None]
    return v / np.where(length > 0, length, 1.0)


def corner_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Shading normals at each face corner: (F, 3, 3) float64 unit vectors, creased per pair of faces.

    vertices : (V, 3) float64;  faces : (F, 3) int64
    A corner's normal is the mean of the normals of the faces around its vertex that lie within the
    crease angle of its own face, each weighted by its angle at that vertex. Where no pair of faces
    around a vertex creases this is trimesh's ``vertex_normals``; each face of a box keeps its own normal.
    Vectorised (bincounts, and the pairwise test only at vertices that need it), which is what lets a
    wave-deformed sea be re-shaded every frame.
    """
    p0, p1, p2 = (vertices[corner] for corner in faces.T)  # three contiguous gathers: twice as fast as (F, 3, 3)
    edge_01, edge_02 = p1 - p0, p2 - p0
    face_n = _unit(np.cross(edge_01, edge_02))  # (F, 3); zero on a degenerate face, which then weighs nothing
    # corner angles as trimesh weighs them (Thuerrner and Wuethrich 1998): two arccos, the third is the rest
    edge_12 = p2 - p1
    length_01, length_02, length_12 = (np.sqrt(_dot(e, e)) for e in (edge_01, edge_02, edge_12))
    with np.errstate(invalid="ignore", divide="ignore"):  # an edge of length 0: NaN angles, set to 0 below
        cos_0 = _dot(edge_01, edge_02) / (length_01 * length_02)
        cos_1 = -_dot(edge_01, edge_12) / (length_01 * length_12)
    angle = np.empty(faces.shape)
    angle[:, 0] = np.arccos(np.clip(cos_0, -1.0, 1.0))
    angle[:, 1] = np.arccos(np.clip(cos_1, -1.0, 1.0))
    angle[:, 2] = np.pi - angle[:, 0] - angle[:, 1]
    np.nan_to_num(angle, copy=False, nan=0.0)

    # ---- all faces around a vertex: kept at every vertex where no pair of its faces creases ----
    index = faces.ravel()
    vertex_n = _unit(
        np.stack([np.bincount(index, (angle * face_n[:, k, None]).ravel(), len(vertices)) for k in range(3)], 1)
    )
    corner_n = vertex_n[faces]
    far = np.einsum("fck,fk->fc", corner_n, face_n) < _HALF_CREASE_COS
    creased = (np.bincount(index[far.ravel()], minlength=len(vertices)) > 0)[index]

    # ---- at the others, each corner against every corner of its vertex ----
    if creased.any():
        corners = np.flatnonzero(creased)  # flat corner index: 3 * face + k
        by_vertex = np.argsort(index, kind="stable")
        valence = np.bincount(index, minlength=len(vertices))
        first = np.cumsum(valence) - valence  # where each vertex's corners start in by_vertex
        size = valence[index[corners]]
        pair = np.repeat(np.arange(len(corners)), size)  # the corner of ``corners`` each pair belongs to
        rank = np.arange(len(pair)) - np.repeat(np.cumsum(size) - size, size)
        other = by_vertex[np.repeat(first[index[corners]], size) + rank]  # flat corner index
        own_n, other_n = face_n[corners // 3], face_n[other // 3]
        smooth_weight = angle.ravel()[other] * (_dot(own_n[pair], other_n) >= CREASE_COS)
        summed = np.stack([np.bincount(pair, smooth_weight * other_n[:, k], len(corners)) for k in range(3)], 1)
        # a degenerate face finds no face within the crease, itself included: it keeps its zero normal
        corner_n.reshape(-1, 3)[corners] = _unit(summed)
    return corner_n


def repaired(part: Part, source: str, tally: Counter | None = None) -> Part:
    """Drop faces with non-finite vertices or zero area, warning with counts; refuse an empty result.

    With a ``tally``, the counts (``faces``, ``non-finite``, ``zero area``) add up there instead, for one
    warning about a whole file of many meshes.
    """
    tri = part.vertices[part.faces]
    finite = np.all(np.isfinite(tri), axis=(1, 2))
    with np.errstate(invalid="ignore", over="ignore"):
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    keep = finite & (area2 > 1e-20)
    counts = Counter({"faces": len(keep), "non-finite": int((~finite).sum()), "zero area": int((finite & ~keep).sum())})
    if tally is not None:
        tally.update(counts)
    elif not keep.all():
        log.warning("%s: %s", source, dropped_faces(counts))
    if not keep.any():
        raise MeshError(f"{source}: mesh has no usable triangles")
    uv = None if part.corner_uv is None else part.corner_uv[keep]
    if uv is not None and not np.all(np.isfinite(uv)):
        log.warning("%s: non-finite texture coordinates replaced by 0", source)
        uv = np.nan_to_num(uv, nan=0.0, posinf=0.0, neginf=0.0)
    return replace(part, faces=part.faces[keep], corner_colors=part.corner_colors[keep], corner_uv=uv)


def dropped_faces(counts: Counter) -> str:
    dropped = counts["non-finite"] + counts["zero area"]
    return (
        f"dropped {dropped} of {counts['faces']} faces ({counts['non-finite']} with non-finite vertices, "
        f"{counts['zero area']} with zero area)"
    )


@dataclass
class Model:
    """A model file's parts, and the cameras and lights it carries (a glTF's; none for other kinds)."""

    parts: list[Part]
    viewpoints: list[gltf.Viewpoint] = field(default_factory=list)
    lights: list[gltf.PunctualLight] = field(default_factory=list)
    motions: list[CameraMotion] = field(default_factory=list)  # its animated cameras (a glTF's)


def _image_array(image) -> np.ndarray:
    """A PIL image's colors as (h, w, 3) uint8 RGB."""
    return np.ascontiguousarray(np.asarray(image.convert("RGB"), dtype=np.uint8))


def _alpha_array(image) -> np.ndarray | None:
    """A PIL image's alpha as (h, w) uint8, or None when it has none or is opaque everywhere."""
    if image.mode in ("RGBA", "LA", "PA", "RGBa", "La") or (image.mode == "P" and "transparency" in image.info):
        alpha = np.asarray(image.convert("RGBA").getchannel("A"), dtype=np.uint8)
        return alpha if alpha.min() < 255 else None
    return None


def rgb8(texture: np.ndarray) -> np.ndarray:
    """A texture as (h, w, 3) uint8: as it is, or from (h, w, 3|4) uint8 or floats in [0, 1] (rounded)."""
    if texture.dtype != np.uint8:
        texture = np.round(np.clip(texture, 0.0, 1.0) * 255.0).astype(np.uint8)
    return texture if texture.shape[-1] == 3 else np.ascontiguousarray(texture[..., :3])


def packed(parts: list[Part]) -> list[Part]:
    """``parts`` with every distinct texture (colors and emission) moved into one (T, 3) uint8 store, each
    part's a view of it: the scene's geometry then takes the store as it is (``scene.build_geometry``)
    rather than a second copy of every texel. Each texture's own array is let go as soon as it is copied,
    so the store costs no second copy while it fills (its pages are touched only as they are written)."""
    parts = list(parts)
    users: dict[int, list[tuple[int, str]]] = {}  # id(image) -> (part index, "texture" or "emission")
    images: dict[int, np.ndarray] = {}
    for k, part in enumerate(parts):
        for slot, image in (("texture", part.texture), ("emission", part.material.emission_texture)):
            if image is not None:
                images.setdefault(id(image), image)
                users.setdefault(id(image), []).append((k, slot))
    bases = {id(_base(image)) for image in images.values()}
    if not images or (len(bases) == 1 and _base(next(iter(images.values()))).ndim == 2):
        return parts  # none, or all in one store already
    store = np.empty((sum(im.shape[0] * im.shape[1] for im in images.values()), 3), np.uint8)
    start = 0
    for key in list(images):
        image = images.pop(key)
        size = image.shape[0] * image.shape[1]
        view = store[start : start + size].reshape(image.shape[0], image.shape[1], 3)
        view[:] = rgb8(image)
        start += size
        del image
        for k, slot in users[key]:
            part = parts[k]
            if slot == "texture":
                parts[k] = replace(part, texture=view)
            else:
                parts[k] = replace(part, material=replace(part.material, emission_texture=view))
    return parts


def _base(image: np.ndarray) -> np.ndarray:
    """The array whose memory ``image`` views (itself when it owns its memory)."""
    while isinstance(image.base, np.ndarray):
        image = image.base
    return image


def release_freed_memory() -> None:
    """Hands memory that was freed back to the system (glibc keeps freed heap pages otherwise, and a loaded
    model has just freed hundreds of MB of trimesh's and Pillow's); nothing elsewhere."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def texture_floats(texture: np.ndarray) -> np.ndarray:
    """An 8-bit texture's colors as (h, w, 3) float32 in [0, 1] (the environment keeps floats)."""
    return texture[..., :3].astype(np.float32) / 255.0


def read_image(path: Path) -> np.ndarray:
    """An image file's colors as (h, w, 3) uint8 RGB."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            return _image_array(image)
    except (OSError, UnidentifiedImageError) as exc:
        raise MeshError(f"{path}: cannot read the image ({exc})") from None


def load_texture(path: Path) -> np.ndarray:
    """An image file as (h, w, 3) float32 in [0, 1]."""
    return texture_floats(read_image(path))


def _rgb(values) -> np.ndarray:
    """Colors as trimesh hands them (uint8, uint16 or float) as (n, 3) float32 in [0, 1]."""
    a = np.asarray(values)
    scale = float(np.iinfo(a.dtype).max) if np.issubdtype(a.dtype, np.integer) else 1.0
    return (a[..., :3].astype(np.float32) / scale).astype(np.float32)


def _fitted(alpha: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``alpha`` (h', w') uint8 resized to ``shape`` (h, w) when it differs (bilinear)."""
    from PIL import Image

    if alpha.shape == shape:
        return alpha
    return np.asarray(Image.fromarray(alpha).resize((shape[1], shape[0]), Image.BILINEAR), dtype=np.uint8)


def _obj_alpha(material, folder: Path | None, images: dict) -> tuple[np.ndarray | None, float]:
    """OBJ's ``map_d`` (its alpha channel, else its luminance) and ``d`` of a trimesh SimpleMaterial."""
    from PIL import Image

    kwargs = getattr(material, "kwargs", None) or {}
    try:
        dissolve = float(kwargs.get("d", ["1"])[0])
    except (TypeError, ValueError, IndexError):
        dissolve = 1.0
    names = kwargs.get("map_d")
    alpha = None
    if names and folder is not None:
        path = folder / " ".join(names)[-200:].split()[-1]
        key = ("map_d", str(path))
        if key not in images:
            try:
                with Image.open(path) as image:
                    images[key] = np.asarray(image.getchannel("A") if "A" in image.getbands() else image.convert("L"))
            except (OSError, ValueError) as exc:
                log.warning("%s: cannot read the map_d image %s (%s); the material is opaque", folder, path.name, exc)
                images[key] = None
        alpha = images[key]
    return alpha, dissolve if np.isfinite(dissolve) else 1.0


def _part_from_trimesh(
    mesh: trimesh.Trimesh,
    world_from_mesh: np.ndarray,
    source: str,
    tally: Counter,
    images: dict,
    materials: list[gltf.MaterialInfo] | None = None,
    folder: Path | None = None,
) -> Part | None:
    """A part from one trimesh placed by the file's transform; ``images`` caches textures by identity,
    since a file's meshes share few images (the staircase interior: 348 textured meshes, 9 images).
    ``materials``: a glTF's (``gltf.extras``), found again by the names ``gltf.renamed_materials`` gave;
    ``folder``: where an OBJ's ``map_d`` lies. None: the mesh is wholly transparent (alpha below its cutoff)."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite vertices are repaired just below
        vertices = np.asarray(mesh.vertices, dtype=np.float64) @ world_from_mesh[:3, :3].T + world_from_mesh[:3, 3]
    visual = mesh.visual
    kind = getattr(visual, "kind", None)
    material = getattr(visual, "material", None)
    if material is not None:
        surface = _material_surface(mesh, faces, material, images, materials, folder)
        if surface is None:
            return None
        colors, uv, texture, material_out = surface
        colored = True
    else:
        colors, uv, texture, material_out = _grey(len(faces)), None, None, PLAIN
        colored = kind in ("texture", "vertex", "face")
        if kind == "vertex":
            colors = _rgb(visual.vertex_colors)[faces]
        elif kind == "face":
            face_rgb = _rgb(visual.face_colors)
            colors = np.repeat(face_rgb[:, None, :], 3, axis=1)
    part = repaired(Part(vertices, faces, colors, uv, texture, colored, material_out), source, tally)
    # weld corners that share a position (a triangle soup, UV seams) so normals shade smooth across
    # them; colors and UVs live per corner, so welding changes nothing else
    unique, inverse = trimesh.grouping.unique_rows(part.vertices[part.faces].reshape(-1, 3), digits=8)
    welded = part.vertices[part.faces].reshape(-1, 3)[unique]
    return replace(part, vertices=welded, faces=inverse.reshape(-1, 3).astype(np.int64))


def _material_surface(
    mesh: trimesh.Trimesh,
    faces: np.ndarray,
    material: Any,
    images: dict,
    materials: list[gltf.MaterialInfo] | None,
    folder: Path | None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, Material] | None:
    """What a mesh with a material shows: its corners' colors, UVs, texture and :class:`Material`; None when the
    material is wholly transparent (alpha below its cutoff)."""
    visual = mesh.visual
    kind = getattr(visual, "kind", None)
    colors = _grey(len(faces))
    uv = texture = None
    colors[:] = 1.0  # glTF's base color factor and OBJ's Kd default to white over a texture
    image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
    index = gltf.material_index(getattr(material, "name", None))
    info = materials[index] if materials is not None and index is not None and index < len(materials) else None
    if info is not None:  # a glTF material: its factors from the JSON, as floats and display colors
        colors[:] = np.asarray(info.base_color, dtype=np.float32)
    else:
        factor = getattr(material, "baseColorFactor", None)
        if factor is None:
            factor = getattr(material, "diffuse", None)
        if factor is not None:
            colors[:] = np.asarray(factor, dtype=np.float32)[:3] / 255.0
    vertex_rgb = getattr(visual, "vertex_attributes", {}).get("color")
    if vertex_rgb is not None and len(vertex_rgb) == len(mesh.vertices):  # glTF's COLOR_0 beside a texture
        colors *= gltf.display(_rgb(vertex_rgb)).astype(np.float32)[faces]
    # a material without an image is a flat color (a texture trimesh failed to read is reported by
    # load_mesh_file, from trimesh's own log)
    has_uv = getattr(visual, "uv", None) is not None and len(visual.uv) == len(mesh.vertices)
    if has_uv:
        uv = np.asarray(visual.uv, dtype=np.float32)[faces]
        if info is not None and info.uv_transform is not None:
            uv = gltf.transformed_uv(uv, info.uv_transform)
    if image is not None and has_uv:
        texture = images.decoded(image)
    if info is not None:
        material_of = _gltf_material(info, material, image, texture, images, has_uv)
    elif kind == "texture" or image is not None:  # OBJ: map_d and d
        material_of = _obj_material(material, folder, images, texture, has_uv)
    else:
        material_of = texture, Material((0.0, 0.0, 0.0), None, False, 0.0, None)
    if material_of is None:
        return None
    texture, shading = material_of
    if texture is None and shading.emission_texture is None:
        uv = None
    return colors, uv, texture, shading


def _gltf_material(
    info: gltf.MaterialInfo, material: Any, image: Any, texture: np.ndarray | None, images: dict, has_uv: bool
) -> tuple[np.ndarray | None, Material] | None:
    """A glTF material's texture and :class:`Material`: its alpha (a cutoff over the base color texture's alpha,
    scaled by the base color's coverage), emission and unlit flag; None when its coverage is below its cutoff."""
    alpha_texture, emission_texture = None, None
    coverage = info.alpha if info.alpha_mode != "OPAQUE" else 1.0
    if coverage < info.alpha_cutoff and info.alpha_mode != "OPAQUE":
        return None
    alpha_texture = images.alphas.get(id(image)) if texture is not None and info.alpha_mode != "OPAQUE" else None
    alpha_cutoff = info.alpha_cutoff / coverage if alpha_texture is not None else 0.0
    emissive_image = getattr(material, "emissiveTexture", None)
    if info.has_emissive_texture and emissive_image is not None and has_uv:
        emission_texture = images.decoded(emissive_image)
    return texture, Material(info.emissive, emission_texture, info.unlit, alpha_cutoff, alpha_texture)


def _obj_material(
    material: Any, folder: Path | None, images: dict, texture: np.ndarray | None, has_uv: bool
) -> tuple[np.ndarray | None, Material] | None:
    """An OBJ material's texture and :class:`Material`: ``map_d`` cut out of the texture at 0.5 (out of a white
    texture without ``map_Kd``); None when its ``d`` dissolves it (below 0.5)."""
    alpha_texture, alpha_cutoff = None, 0.0
    alpha, dissolve = _obj_alpha(material, folder, images)
    if dissolve < 0.5:
        return None
    if alpha is not None and has_uv and alpha.min() < 255:
        if texture is None:  # map_d without map_Kd: a white texture to cut out of
            key = ("white", alpha.shape)
            if key not in images:
                images[key] = np.full(alpha.shape + (3,), 255, np.uint8)
            texture = images[key]
        key = ("map_d", id(alpha), texture.shape[:2])
        if key not in images:
            images[key] = _fitted(alpha, texture.shape[:2])
        alpha_texture, alpha_cutoff = images[key], 0.5
    return texture, Material((0.0, 0.0, 0.0), None, False, alpha_cutoff, alpha_texture)


class _Images(dict):
    """A file's images, each decoded once, straight into one (T, 3) uint8 store sized up front from the
    images' headers (trimesh's images are not decoded until asked), and Pillow's copy closed at once: the
    staircase interior's 9 images never exist twice. An image's alpha is kept apart (``alphas``), and only
    when it is not opaque everywhere. Other arrays made while reading (OBJ's ``map_d``) are kept by key."""

    def __init__(self, meshes: list):
        super().__init__()
        distinct = {}
        for mesh, _ in meshes:
            material = getattr(mesh.visual, "material", None)
            for name in ("baseColorTexture", "image", "emissiveTexture"):
                image = getattr(material, name, None)
                if image is not None and hasattr(image, "size"):
                    distinct.setdefault(id(image), image.size)
        self.slots, start = {}, 0
        for key, (width, height) in distinct.items():
            self.slots[key] = (start, width, height)
            start += width * height
        self.store = np.empty((start, 3), np.uint8)  # pages are touched only as images are written
        self.alphas: dict[int, np.ndarray] = {}

    def decoded(self, image) -> np.ndarray:
        """``image`` (a PIL image) as (h, w, 3) uint8 RGB; its alpha, if any, into ``alphas``."""
        key = id(image)
        if key not in self:
            if key in self.slots and image.size == self.slots[key][1:]:
                start, width, height = self.slots[key]
                view = self.store[start : start + width * height].reshape(height, width, 3)
                view[:] = _image_array(image)
                self[key] = view
            else:
                self[key] = _image_array(image)
            alpha = _alpha_array(image)
            if alpha is not None:
                self.alphas[key] = alpha
            image.close()  # its decoded pixels: the store holds them now
        return self[key]


class _TrimeshTroubles(logging.Handler):
    """Collects what trimesh says while it loads a file: it reports an unreadable texture only in its
    debug log, and goes on without it."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        cause = f" ({type(record.exc_info[1]).__name__}: {record.exc_info[1]})" if record.exc_info else ""
        if "failed to load image" in record.getMessage():
            self.messages.append(f"a texture image could not be read{cause}; its material shows its flat color")
        elif record.levelno >= logging.WARNING:
            self.messages.append(record.getMessage() + cause)


def load_mesh_file(path: Path, refuse_nonfinite: bool = False) -> list[Part]:
    """Every mesh of a file (OBJ, PLY, STL, GLB/glTF, ...), with the file's own transforms applied
    (:func:`load_model`'s parts)."""
    return load_model(path, refuse_nonfinite).parts


def _read_trimesh_scene(path: Path) -> tuple[trimesh.Scene, gltf.GltfExtras | None]:
    """trimesh's scene of the file, and for a glTF what trimesh drops (its materials found again by name)."""
    suffix = path.suffix.lower()
    if suffix not in (".glb", ".gltf"):
        # process=False: trimesh would silently drop non-finite vertices; repaired() reports them
        return trimesh.load_scene(str(path), process=False), None
    glb = suffix == ".glb"
    data = path.read_bytes()
    try:
        document, binary = gltf.split(data, glb)
        found = gltf.extras(document)
        found.motions = gltf.camera_motions(document, binary, path.parent)
        data = gltf.joined(gltf.renamed_materials(document), binary, glb)
    except gltf.GltfError as exc:
        raise MeshError(f"{path}: {exc}") from None
    import io

    resolver = trimesh.resolvers.FilePathResolver(str(path))
    loaded = trimesh.load_scene(io.BytesIO(data), file_type=suffix[1:], resolver=resolver, process=False)
    del data
    return loaded, found


def _read_meshes(path: Path) -> tuple[list, Any]:
    """Every mesh of the file with triangles, and its world transform (n, 4, 4) float64; and what the file says
    beside them (a glTF's cameras, lights and materials), or None. trimesh's complaints are logged once each."""
    troubles = _TrimeshTroubles()
    trimesh_log = logging.getLogger("trimesh")
    trimesh_log.addHandler(troubles)
    level = trimesh_log.level
    trimesh_log.setLevel(logging.DEBUG)
    try:
        loaded, found = _read_trimesh_scene(path)
        # walk the scene graph rather than dump(): dump() copies every mesh and its texture image
        meshes = []
        for node in loaded.graph.nodes_geometry:
            world_from_mesh, name = loaded.graph[node]
            mesh = loaded.geometry.get(name)
            if isinstance(mesh, trimesh.Trimesh) and len(mesh.faces):
                meshes.append((mesh, np.asarray(world_from_mesh, dtype=np.float64)))
    except MeshError:
        raise
    except Exception as exc:  # trimesh raises anything from ValueError to KeyError on a bad file
        raise MeshError(f"{path}: trimesh cannot read it ({type(exc).__name__}: {exc})") from None
    finally:
        trimesh_log.removeHandler(troubles)
        trimesh_log.setLevel(level)
    for message in dict.fromkeys(troubles.messages):  # each distinct complaint once
        log.warning("%s: %s", path, message)
    if not meshes:
        raise MeshError(f"{path}: the file holds no triangles")
    return meshes, found


def load_model(path: Path, refuse_nonfinite: bool = False) -> Model:
    """Every mesh of a file (OBJ, PLY, STL, GLB/glTF, ...), with the file's own transforms applied, and
    a glTF's cameras and lights.

    Meshes of the file with no usable triangle are skipped with a warning; a file with none is an error.
    ``refuse_nonfinite``: a vertex that is not a finite number is an error, not a repair (files from strangers).
    """
    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: no such mesh file")
    meshes, found = _read_meshes(path)
    parts, unusable, hidden, tally, images = [], 0, 0, Counter(), _Images(meshes)
    materials = found.materials if found is not None else None
    for mesh, world_from_mesh in meshes:
        try:
            part = _part_from_trimesh(mesh, world_from_mesh, str(path), tally, images, materials, path.parent)
        except MeshError:
            unusable += 1
            continue
        if part is None:
            hidden += 1
        else:
            parts.append(part)
    mesh_count = len(meshes)
    # trimesh's scene holds its meshes and decoded images in reference cycles: collect them now, not at
    # the next cyclic collection (the staircase interior: 100 MB held for nothing until then)
    del meshes, images
    gc.collect()
    if refuse_nonfinite and tally["non-finite"]:
        raise MeshError(
            f"{path}: {tally['non-finite']:,} of {tally['faces']:,} triangles have vertices that are not finite "
            "numbers (NaN or infinity)"
        )
    if tally["non-finite"] or tally["zero area"]:
        log.warning("%s: %s", path, dropped_faces(tally))
    if unusable and parts:
        log.warning("%s: skipped %d of %d meshes that hold no usable triangle", path, unusable, mesh_count)
    if hidden:
        log.info("%s: %d meshes are wholly transparent (alpha below their cutoff) and left out", path, hidden)
    if not parts:
        raise MeshError(f"{path}: the file holds no usable triangles")
    parts = packed(parts)
    release_freed_memory()
    if found is None:
        return Model(parts)
    return Model(parts, found.viewpoints, found.lights, found.motions)


# ---- primitives: base on y = 0 and axis along +y (box, cylinder, cone); sphere about the origin ----


def _y_up(mesh: trimesh.Trimesh, lift: float) -> trimesh.Trimesh:
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-math.pi / 2, [1, 0, 0]))
    mesh.apply_translation([0.0, lift, 0.0])
    return mesh


def grid(size=(10.0, 10.0), divisions=(10, 10), uv_repeat=(1.0, 1.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A subdivided rectangle in the xz plane facing +y: vertices (V,3), faces (F,3), uv (V,2)."""
    nx, nz = int(divisions[0]), int(divisions[1])
    x = np.linspace(-size[0] / 2, size[0] / 2, nx + 1)
    z = np.linspace(-size[1] / 2, size[1] / 2, nz + 1)
    zz, xx = np.meshgrid(z, x, indexing="ij")
    vertices = np.stack([xx.ravel(), np.zeros(xx.size), zz.ravel()], axis=1)
    uv = np.stack([(xx.ravel() / size[0] + 0.5) * uv_repeat[0], (0.5 - zz.ravel() / size[1]) * uv_repeat[1]], 1)
    a = (np.arange(nz)[:, None] * (nx + 1) + np.arange(nx)[None, :]).ravel()
    b, c, d = a + 1, a + nx + 1, a + nx + 2
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    return vertices, faces.astype(np.int64), uv


def primitive(kind: str, **p) -> Part:
    """A procedural mesh: ``box``, ``sphere``, ``cylinder``, ``cone`` or ``grid`` (with UVs)."""
    if kind == "grid":
        vertices, faces, uv = grid(
            p.get("size", (10.0, 10.0)), p.get("divisions", (10, 10)), p.get("uv_repeat", (1.0, 1.0))
        )
        return Part(vertices, faces, _grey(len(faces)), uv[faces].astype(np.float32))
    if kind == "box":
        mesh = trimesh.creation.box(extents=p.get("extents", (1.0, 1.0, 1.0)))
        mesh.apply_translation([0.0, mesh.extents[1] / 2, 0.0])
    elif kind == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=p.get("subdivisions", 3), radius=p.get("radius", 1.0))
    elif kind == "cylinder":
        height = p.get("height", 1.0)
        mesh = _y_up(
            trimesh.creation.cylinder(radius=p.get("radius", 0.5), height=height, sections=p.get("sections", 24)),
            height / 2,
        )
    elif kind == "cone":
        mesh = _y_up(
            trimesh.creation.cone(
                radius=p.get("radius", 0.5), height=p.get("height", 1.0), sections=p.get("sections", 24)
            ),
            0.0,
        )
    else:
        raise MeshError(f"unknown primitive {kind!r}")
    faces = np.asarray(mesh.faces, dtype=np.int64)
    return Part(np.asarray(mesh.vertices, dtype=np.float64), faces, _grey(len(faces)))
