"""What trimesh drops from a glTF, read from its JSON: the file's cameras and lights
(``KHR_lights_punctual``), its cameras' animations (``motion.py``: translation, rotation and scale of the
camera node and its ancestors, and ``yfov`` through ``KHR_animation_pointer``), and of each material what the
shading model shows (base color factor, alpha mode and cutoff, emissive factor, ``KHR_materials_unlit``,
``KHR_texture_transform``).

trimesh reads the geometry, the images and the UVs; :func:`renamed_materials` gives each material of the
JSON a name that says its index (``rcp-material-<k>``) before trimesh reads it, so that a trimesh
material finds its glTF material again (:func:`material_index`).

Colors: glTF's factors and vertex colors are linear; this renderer's colors are display colors (what an
8-bit texture holds), so factors are encoded to sRGB once here (:func:`display`).
"""

from __future__ import annotations

import base64
import json
import math
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .motion import MAX_CHAIN, CameraMotion, Channel, MotionError, NodeMotion

GLB_MAGIC, GLB_JSON, GLB_BIN = b"glTF", 0x4E4F534A, 0x004E4942
MATERIAL_PREFIX = "rcp-material-"
MAX_VIEWPOINTS = 256  # a file's cameras kept, the first in its order: each is offered to every walker in `ready`
MAX_LIGHTS = 256  # a file's lights kept, the first in its order (the scene lights with one of them)


class GltfError(ValueError):
    """A glTF whose JSON cannot be read."""


@dataclass(frozen=True)
class Viewpoint:
    """A camera of the file, in the file's world space: eye, look_at, up (3 floats each), fov in degrees."""

    name: str
    eye: tuple[float, float, float]
    forward: tuple[float, float, float]  # unit view direction
    up: tuple[float, float, float]
    fov: float


@dataclass(frozen=True)
class PunctualLight:
    """A light of ``KHR_lights_punctual``: its kind, where it stands and where it points (world space)."""

    name: str
    kind: str  # directional, point or spot
    position: tuple[float, float, float]
    direction: tuple[float, float, float]  # the way the light travels (the node's -z), unit length


@dataclass(frozen=True)
class MaterialInfo:
    """What the shading model shows of one glTF material (factors already display colors)."""

    base_color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    alpha: float = 1.0  # baseColorFactor's alpha (linear coverage)
    alpha_mode: str = "OPAQUE"  # OPAQUE, MASK or BLEND
    alpha_cutoff: float = 0.5
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)
    has_emissive_texture: bool = False
    unlit: bool = False
    uv_transform: np.ndarray | None = field(default=None, compare=False)  # (3, 3) on glTF uv, or None


@dataclass
class GltfExtras:
    """Everything of a glTF that trimesh does not keep."""

    viewpoints: list[Viewpoint] = field(default_factory=list)
    lights: list[PunctualLight] = field(default_factory=list)
    materials: list[MaterialInfo] = field(default_factory=list)
    motions: list[CameraMotion] = field(default_factory=list)


def display(linear) -> np.ndarray:
    """Linear [0, 1] values encoded to sRGB display values (the piecewise sRGB curve): float64 array."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def split(data: bytes, glb: bool) -> tuple[dict, bytes]:
    """The JSON (a dict) and the binary chunk of a GLB (``glb``) or of a .gltf's bytes (no binary)."""
    try:
        if not glb:
            return _object(json.loads(data)), b""
        magic, _version, _length = struct.unpack_from("<4sII", data)
        if magic != GLB_MAGIC:
            raise GltfError("not a GLB file")
        offset, gltf, binary = 12, None, b""
        while offset + 8 <= len(data):
            size, kind = struct.unpack_from("<II", data, offset)
            chunk = data[offset + 8 : offset + 8 + size]
            if kind == GLB_JSON and gltf is None:
                gltf = _object(json.loads(chunk))
            elif kind == GLB_BIN and not binary:
                binary = chunk
            offset += 8 + size
    except (ValueError, struct.error, RecursionError) as exc:
        raise GltfError(f"the glTF JSON cannot be read ({str(exc)[:80]})") from None
    if gltf is None:
        raise GltfError("the GLB has no JSON chunk")
    return gltf, binary


def _object(value) -> dict:
    if not isinstance(value, dict):
        raise GltfError("the glTF JSON is not an object")
    return value


def _dict_or_empty(value) -> dict:
    """A JSON object, or {} for anything else (a file's optional fields are read past when malformed)."""
    return value if isinstance(value, dict) else {}


def joined(gltf: dict, binary: bytes, glb: bool) -> bytes:
    """The file's bytes again, with ``gltf`` as its JSON."""
    text = json.dumps(gltf, separators=(",", ":")).encode()
    if not glb:
        return text
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), GLB_JSON) + text
    if binary:
        binary = binary + b"\0" * (-len(binary) % 4)
        chunks += struct.pack("<II", len(binary), GLB_BIN) + binary
    return struct.pack("<4sII", GLB_MAGIC, 2, 12 + len(chunks)) + chunks


def renamed_materials(gltf: dict) -> dict:
    """``gltf`` with every material named by its index, so trimesh's materials can be traced back."""
    for k, material in enumerate(_list(gltf, "materials")):
        material["name"] = f"{MATERIAL_PREFIX}{k}"
    return gltf


def material_index(name) -> int | None:
    """The glTF index a trimesh material's name carries (``renamed_materials``), or None."""
    if isinstance(name, str) and name.startswith(MATERIAL_PREFIX) and name[len(MATERIAL_PREFIX) :].isdigit():
        return int(name[len(MATERIAL_PREFIX) :])
    return None


def _list(gltf: dict, key: str) -> list:
    items = gltf.get(key)
    return [item if isinstance(item, dict) else {} for item in items] if isinstance(items, list) else []


def _indices(value) -> list[int]:
    """The integers of a JSON list (a node's children, a scene's roots); nothing for anything else."""
    return [v for v in value if isinstance(v, int) and not isinstance(v, bool)] if isinstance(value, list) else []


def _numbers(value, count: int, default) -> tuple:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        return default
    return out if len(out) == count and all(math.isfinite(v) for v in out) else default


# ---- the scene graph: node -> world matrix ----


def _local(node: dict) -> np.ndarray:
    matrix = _numbers(node.get("matrix"), 16, None)
    if matrix is not None:
        return np.asarray(matrix, dtype=np.float64).reshape(4, 4).T  # column-major in the file
    t = _numbers(node.get("translation"), 3, (0.0, 0.0, 0.0))
    x, y, z, w = _numbers(node.get("rotation"), 4, (0.0, 0.0, 0.0, 1.0))
    s = _numbers(node.get("scale"), 3, (1.0, 1.0, 1.0))
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = rotation * np.asarray(s)
    m[:3, 3] = t
    return m


def world_matrices(gltf: dict) -> dict[int, np.ndarray]:
    """World matrix (4x4 float64) of every node reachable from the default scene's roots (or from every
    node that is no one's child, when the file names no scene)."""
    nodes = _list(gltf, "nodes")
    scenes = _list(gltf, "scenes")
    index = gltf.get("scene", 0)
    if scenes:
        scene = scenes[index] if isinstance(index, int) and 0 <= index < len(scenes) else scenes[0]
        roots = _indices(scene.get("nodes"))
    else:
        children = {c for node in nodes for c in _indices(node.get("children"))}
        roots = [k for k in range(len(nodes)) if k not in children]
    world: dict[int, np.ndarray] = {}
    stack = [(r, np.eye(4)) for r in roots]
    while stack:
        k, parent = stack.pop()
        if not (isinstance(k, int) and 0 <= k < len(nodes)) or k in world:  # a bad index, or a cycle
            continue
        world[k] = parent @ _local(nodes[k])
        stack.extend((c, world[k]) for c in _indices(nodes[k].get("children")))
    return world


def _unit(v: np.ndarray) -> np.ndarray | None:
    length = float(np.linalg.norm(v))
    return v / length if length > 1e-12 and math.isfinite(length) else None


def triple(v) -> tuple[float, float, float]:
    """Three numbers of ``v`` as a typed 3-tuple of floats."""
    return (float(v[0]), float(v[1]), float(v[2]))


# ---- what trimesh drops ----


def extras(gltf: dict) -> GltfExtras:
    """The cameras, lights and materials of a glTF's JSON, in the file's order (a camera or light that
    no node of the scene places is left out; so is an orthographic camera); at most :data:`MAX_VIEWPOINTS`
    cameras and :data:`MAX_LIGHTS` lights, the first ones."""
    out = GltfExtras(materials=[_material(m) for m in _list(gltf, "materials")])
    nodes = _list(gltf, "nodes")
    cameras = _list(gltf, "cameras")
    lights = _list(
        gltf.get("extensions", {}).get("KHR_lights_punctual", {}) if isinstance(gltf.get("extensions"), dict) else {},
        "lights",
    )
    for k, m in sorted(world_matrices(gltf).items()):
        node = nodes[k]
        eye = m[:3, 3]
        forward = _unit(m[:3, :3] @ [0.0, 0.0, -1.0])
        up = _unit(m[:3, :3] @ [0.0, 1.0, 0.0])
        if forward is None or up is None or not np.all(np.isfinite(eye)):
            continue
        cam = node.get("camera")
        if len(out.viewpoints) >= MAX_VIEWPOINTS:
            cam = None  # a bound: a small file can place a camera on each of 60,000 nodes
        if isinstance(cam, int) and 0 <= cam < len(cameras) and cameras[cam].get("type") == "perspective":
            perspective = cameras[cam].get("perspective")
            yfov = perspective.get("yfov") if isinstance(perspective, dict) else None
            if isinstance(yfov, (int, float)) and 0 < yfov < math.pi:
                name = str(cameras[cam].get("name") or node.get("name") or f"camera {len(out.viewpoints) + 1}")
                out.viewpoints.append(
                    Viewpoint(name, triple(eye), triple(forward), triple(up), math.degrees(float(yfov)))
                )
        light = (
            node.get("extensions", {}).get("KHR_lights_punctual", {})
            if isinstance(node.get("extensions"), dict)
            else {}
        )
        index = light.get("light") if isinstance(light, dict) and len(out.lights) < MAX_LIGHTS else None
        if isinstance(index, int) and 0 <= index < len(lights):
            spec = lights[index]
            kind = spec.get("type") if spec.get("type") in ("directional", "point", "spot") else "point"
            name = str(spec.get("name") or node.get("name") or f"light {len(out.lights) + 1}")
            out.lights.append(PunctualLight(name, kind, triple(eye), triple(forward)))
    return out


def _material(material: dict) -> MaterialInfo:
    pbr = material.get("pbrMetallicRoughness")
    pbr = pbr if isinstance(pbr, dict) else {}
    factor = _numbers(pbr.get("baseColorFactor"), 4, (1.0, 1.0, 1.0, 1.0))
    mode = str(material.get("alphaMode")) if material.get("alphaMode") in ("OPAQUE", "MASK", "BLEND") else "OPAQUE"
    cutoff = material.get("alphaCutoff", 0.5)
    cutoff = float(cutoff) if isinstance(cutoff, (int, float)) and math.isfinite(cutoff) else 0.5
    extensions = _dict_or_empty(material.get("extensions"))
    texture = _dict_or_empty(pbr.get("baseColorTexture"))
    transform = (
        texture.get("extensions", {}).get("KHR_texture_transform")
        if isinstance(texture.get("extensions"), dict)
        else None
    )
    return MaterialInfo(
        base_color=tuple(display(factor[:3]).tolist()),
        alpha=min(max(factor[3], 0.0), 1.0),
        alpha_mode=mode,
        alpha_cutoff=cutoff if mode == "MASK" else 0.5,  # BLEND is drawn as a mask at one half
        emissive=tuple(display(_numbers(material.get("emissiveFactor"), 3, (0.0, 0.0, 0.0))).tolist()),
        has_emissive_texture=isinstance(material.get("emissiveTexture"), dict),
        unlit="KHR_materials_unlit" in extensions,
        uv_transform=uv_transform(transform) if isinstance(transform, dict) else None,
    )


def uv_transform(spec: dict) -> np.ndarray:
    """``KHR_texture_transform`` as a 3x3 matrix on glTF uv (origin at the image's top left):
    translation . rotation . scale, as the extension defines them."""
    ox, oy = _numbers(spec.get("offset"), 2, (0.0, 0.0))
    sx, sy = _numbers(spec.get("scale"), 2, (1.0, 1.0))
    angle = spec.get("rotation", 0.0)
    angle = float(angle) if isinstance(angle, (int, float)) and math.isfinite(angle) else 0.0
    c, s = math.cos(angle), math.sin(angle)
    translation = np.array([[1.0, 0.0, ox], [0.0, 1.0, oy], [0.0, 0.0, 1.0]])
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    scale = np.diag([sx, sy, 1.0])
    return translation @ rotation @ scale


def transformed_uv(uv: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """trimesh's uv (origin bottom left: v flipped from glTF's) moved by a glTF texture transform: (..., 2)
    float32."""
    u, v = uv[..., 0].astype(np.float64), 1.0 - uv[..., 1].astype(np.float64)
    tu = matrix[0, 0] * u + matrix[0, 1] * v + matrix[0, 2]
    tv = matrix[1, 0] * u + matrix[1, 1] * v + matrix[1, 2]
    return np.stack([tu, 1.0 - tv], axis=-1).astype(np.float32)


# ---- animated cameras ----

FLOAT = 5126
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
YFOV_POINTER = re.compile(r"/cameras/(\d+)/perspective/yfov")


def _accessor(gltf: dict, buffers: list[bytes], index) -> np.ndarray:
    """Accessor ``index`` as ``(count, width)`` float64: float keys only (what Blender writes); GltfError else."""
    accessors, views = _list(gltf, "accessors"), _list(gltf, "bufferViews")
    if not (isinstance(index, int) and 0 <= index < len(accessors)):
        raise GltfError(f"an animation reads accessor {index!r}, which the file does not have")
    accessor = accessors[index]
    width = WIDTHS.get(accessor.get("type"))
    count, view_index = accessor.get("count"), accessor.get("bufferView")
    if accessor.get("componentType") != FLOAT or width is None or not isinstance(count, int) or count < 0:
        raise GltfError(f"accessor {index}: an animation's keys must be float scalars or vectors")
    if not (isinstance(view_index, int) and 0 <= view_index < len(views)):
        raise GltfError(f"accessor {index}: no buffer view")
    view = views[view_index]
    buffer = view.get("buffer", 0)
    if not (isinstance(buffer, int) and 0 <= buffer < len(buffers)):
        raise GltfError(f"accessor {index}: no buffer {buffer!r}")
    stride = view.get("byteStride") or 4 * width
    start = int(view.get("byteOffset", 0) or 0) + int(accessor.get("byteOffset", 0) or 0)
    if count > 3 * 100_000 + 3 or not isinstance(stride, int) or stride < 4 * width:
        raise GltfError(f"accessor {index}: {count:,} keys, more than an animation may have")
    data = buffers[buffer]
    end = start + (count - 1) * stride + 4 * width if count else start
    if start < 0 or end > len(data):
        raise GltfError(f"accessor {index}: reads past the end of its buffer")
    rows = np.ndarray((count, width), np.dtype("<f4"), data, start, (stride, 4)) if count else np.zeros((0, width))
    return rows.astype(np.float64)


def _buffers(gltf: dict, binary: bytes, folder: Path | None) -> list[bytes]:
    """The bytes of every buffer: the GLB's chunk, a ``data:`` URI, or a file beside the model."""
    out = []
    for k, buffer in enumerate(_list(gltf, "buffers")):
        uri = buffer.get("uri")
        if uri is None:
            out.append(binary if k == 0 else b"")
        elif isinstance(uri, str) and uri.startswith("data:") and "," in uri:
            out.append(base64.b64decode(uri.split(",", 1)[1], validate=False))
        elif isinstance(uri, str) and folder is not None and "/" not in uri and not uri.startswith("."):
            file = folder / uri
            out.append(file.read_bytes() if file.is_file() else b"")
        else:
            out.append(b"")
    return out


def _node_motion(node: dict, channels: list[Channel]) -> NodeMotion:
    matrix = _numbers(node.get("matrix"), 16, None)
    return NodeMotion(
        _numbers(node.get("translation"), 3, (0.0, 0.0, 0.0)),
        _numbers(node.get("rotation"), 4, (0.0, 0.0, 0.0, 1.0)),
        _numbers(node.get("scale"), 3, (1.0, 1.0, 1.0)),
        matrix if matrix is not None and not channels else None,
        tuple(channels),
    )


def _animation_targets(gltf: dict, animation: dict) -> list[tuple[object, str, dict]]:
    """An animation's channels as ``(target, path, sampler)``: target a node index, or ``("camera", k)``."""
    samplers = _list(animation, "samplers")
    out: list[tuple[object, str, dict]] = []
    for channel in _list(animation, "channels"):
        target = _dict_or_empty(channel.get("target"))
        sampler = channel.get("sampler")
        if not (isinstance(sampler, int) and 0 <= sampler < len(samplers)):
            continue
        path = target.get("path")
        if path in ("translation", "rotation", "scale") and isinstance(target.get("node"), int):
            out.append((target["node"], str(path), samplers[sampler]))
        elif path == "pointer":
            pointer = _dict_or_empty(_dict_or_empty(target.get("extensions")).get("KHR_animation_pointer"))
            found = YFOV_POINTER.fullmatch(str(pointer.get("pointer", "")))
            if found:
                out.append((("camera", int(found.group(1))), "yfov", samplers[sampler]))
    return out


def camera_motions(gltf: dict, binary: bytes, folder: Path | None = None) -> list[CameraMotion]:
    """The animated cameras of a glTF, each named as its viewpoint is (the camera's name, or its node's): for
    each perspective camera placed by the scene, the first animation that moves its node or an ancestor, or
    animates its ``yfov``. :class:`GltfError` in one line for an animation refused (too long, too many keys,
    keys that are not finite numbers)."""
    nodes, cameras = _list(gltf, "nodes"), _list(gltf, "cameras")
    animations = _list(gltf, "animations")
    if not animations:
        return []
    parent = {c: k for k, node in enumerate(nodes) for c in _indices(node.get("children"))}
    buffers: list[bytes] | None = None
    motions: list[CameraMotion] = []
    for k in sorted(world_matrices(gltf)):
        cam = nodes[k].get("camera")
        if not (isinstance(cam, int) and 0 <= cam < len(cameras) and cameras[cam].get("type") == "perspective"):
            continue
        chain = [k]
        while chain[-1] in parent and len(chain) <= MAX_CHAIN:
            chain.append(parent[chain[-1]])
        chain.reverse()
        name = str(cameras[cam].get("name") or nodes[k].get("name") or f"camera {len(motions) + 1}")
        for animation in animations:
            targets = [t for t in _animation_targets(gltf, animation) if t[0] in chain or t[0] == ("camera", cam)]
            if not targets:
                continue
            buffers = buffers if buffers is not None else _buffers(gltf, binary, folder)
            try:
                channels: dict[object, list[Channel]] = {}
                for target, path, sampler in targets:
                    times = _accessor(gltf, buffers, sampler.get("input"))[:, 0]
                    values = _accessor(gltf, buffers, sampler.get("output"))
                    interpolation = str(sampler.get("interpolation", "LINEAR"))
                    channels.setdefault(target, []).append(Channel(path, interpolation, times, values))
                perspective = _dict_or_empty(cameras[cam].get("perspective"))
                fov = channels.get(("camera", cam), [None])[0]
                motions.append(
                    CameraMotion(
                        name[:80],
                        tuple(_node_motion(nodes[n], channels.get(n, [])) for n in chain),
                        float(perspective.get("yfov", 0.0) or 0.0),
                        fov,
                    )
                )
            except MotionError as exc:
                raise GltfError(f"the animation of camera {name[:80]!r}: {exc}") from None
            break
    return motions
