"""Triangle meshes with their surface colors: loaded from files through trimesh, or built as primitives.

Every mesh becomes a :class:`Part`: vertices and faces plus per-corner shading data (colors, UVs, one
optional texture), whatever the source carried: a texture through UVs, vertex colors, face colors, or a
flat color. Broken input is repaired with a warning (non-finite vertices, zero-area faces) or refused
with a :class:`MeshError` naming the file.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import trimesh

log = logging.getLogger("rcp")

DEFAULT_ALBEDO = (0.8, 0.8, 0.8)
# corners whose averaged normal bends further than this from the face keep the face normal: boxes stay
# crisp while spheres and scanned meshes shade smooth
CREASE_COS = math.cos(math.radians(35.0))


class MeshError(ValueError):
    """A mesh that cannot be used; the message names the source and what is wrong."""


@dataclass
class Part:
    """One surface in object space.

    vertices : (V, 3) float64, scene units;  faces : (F, 3) int64
    corner_colors : (F, 3, 3) float32, linear [0, 1], multiplied into the texture when there is one
    corner_uv : (F, 3, 2) float32 or None;  texture : (h, w, 3) float32 in [0, 1] or None
    colored : the source carried colors of its own (a texture or material color, vertex or face colors);
    otherwise corner_colors is the default grey
    """

    vertices: np.ndarray
    faces: np.ndarray
    corner_colors: np.ndarray
    corner_uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    colored: bool = False

    def tinted(self, color) -> Part:
        return replace(self, corner_colors=self.corner_colors * np.asarray(color, np.float32).reshape(1, 1, 3))


def _grey(face_count: int) -> np.ndarray:
    return np.broadcast_to(np.float32(DEFAULT_ALBEDO), (face_count, 3, 3)).copy()


def corner_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Shading normals at each face corner: (F, 3, 3) float64 unit vectors, smooth below the crease angle.

    Vertex normals are area-weighted means of the faces around a vertex (a bincount per axis, which is
    what lets a wave-deformed sea be re-shaded every frame).
    """
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = twice the area
    face_n = cross / np.maximum(np.linalg.norm(cross, axis=1, keepdims=True), 1e-30)
    index = faces.ravel()
    vertex_n = np.stack(
        [np.bincount(index, np.repeat(cross[:, k], 3), minlength=len(vertices)) for k in range(3)], axis=1
    )
    vertex_n /= np.maximum(np.linalg.norm(vertex_n, axis=1, keepdims=True), 1e-30)
    corner_n = vertex_n[faces]
    crease = np.einsum("fck,fk->fc", corner_n, face_n) < CREASE_COS
    corner_n[crease] = np.broadcast_to(face_n[:, None, :], corner_n.shape)[crease]
    return corner_n


def repaired(part: Part, source: str) -> Part:
    """Drop faces with non-finite vertices or zero area, warning with counts; refuse an empty result."""
    tri = part.vertices[part.faces]
    finite = np.all(np.isfinite(tri), axis=(1, 2))
    with np.errstate(invalid="ignore", over="ignore"):
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    keep = finite & (area2 > 1e-20)
    if not keep.all():
        log.warning(
            "%s: dropped %d of %d faces (%d with non-finite vertices, %d with zero area)",
            source,
            int((~keep).sum()),
            len(keep),
            int((~finite).sum()),
            int((finite & ~keep).sum()),
        )
    if not keep.any():
        raise MeshError(f"{source}: mesh has no usable triangles")
    uv = None if part.corner_uv is None else part.corner_uv[keep]
    if uv is not None and not np.all(np.isfinite(uv)):
        log.warning("%s: non-finite texture coordinates replaced by 0", source)
        uv = np.nan_to_num(uv, nan=0.0, posinf=0.0, neginf=0.0)
    return replace(part, faces=part.faces[keep], corner_colors=part.corner_colors[keep], corner_uv=uv)


def _image_array(image) -> np.ndarray:
    return np.asarray(image.convert("RGB"), dtype=np.float32) / 255.0


def load_texture(path: Path) -> np.ndarray:
    """An image file as (h, w, 3) float32 in [0, 1]."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            return _image_array(image)
    except (OSError, UnidentifiedImageError) as exc:
        raise MeshError(f"{path}: cannot read texture image ({exc})") from None


def _part_from_trimesh(mesh: trimesh.Trimesh, source: str) -> Part:
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    visual = mesh.visual
    colors = _grey(len(faces))
    uv = texture = None
    kind = getattr(visual, "kind", None)
    colored = kind in ("texture", "vertex", "face")
    if kind == "texture":
        colors[:] = 1.0  # glTF's base color factor and OBJ's Kd default to white over a texture
        material = visual.material
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        factor = getattr(material, "baseColorFactor", None)
        if factor is None:
            factor = getattr(material, "diffuse", None)
        if factor is not None:
            colors[:] = np.asarray(factor, dtype=np.float32)[:3] / 255.0
        if image is not None and visual.uv is not None and len(visual.uv) == len(vertices):
            uv = np.asarray(visual.uv, dtype=np.float32)[faces]
            texture = _image_array(image)
        else:
            log.warning("%s: material has no readable texture; using its flat color", source)
    elif kind == "vertex":
        colors = (np.asarray(visual.vertex_colors, dtype=np.float32)[:, :3] / 255.0)[faces]
    elif kind == "face":
        face_rgb = np.asarray(visual.face_colors, dtype=np.float32)[:, :3] / 255.0
        colors = np.repeat(face_rgb[:, None, :], 3, axis=1)
    part = repaired(Part(vertices, faces, colors, uv, texture, colored), source)
    # weld corners that share a position (a triangle soup, UV seams) so normals shade smooth across
    # them; colors and UVs live per corner, so welding changes nothing else
    unique, inverse = trimesh.grouping.unique_rows(part.vertices[part.faces].reshape(-1, 3), digits=8)
    welded = part.vertices[part.faces].reshape(-1, 3)[unique]
    return replace(part, vertices=welded, faces=inverse.reshape(-1, 3).astype(np.int64))


def load_mesh_file(path: Path) -> list[Part]:
    """Every mesh of a file (OBJ, PLY, STL, GLB/glTF, ...), with the file's own transforms applied."""
    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: no such mesh file")
    try:
        # process=False: trimesh would silently drop non-finite vertices; repaired() reports them
        loaded = trimesh.load_scene(str(path), process=False)
        meshes = [m for m in loaded.dump() if isinstance(m, trimesh.Trimesh)]
    except Exception as exc:  # trimesh raises anything from ValueError to KeyError on a bad file
        raise MeshError(f"{path}: trimesh cannot read it ({type(exc).__name__}: {exc})") from None
    meshes = [m for m in meshes if len(m.faces)]
    if not meshes:
        raise MeshError(f"{path}: the file holds no triangles")
    return [_part_from_trimesh(m, str(path)) for m in meshes]


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
