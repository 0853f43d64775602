"""glTF files built in code, byte for byte: meshes, materials with their extensions, cameras and lights,
exactly as a test wants them (trimesh's exporter writes none of the cameras, lights or extensions)."""

from __future__ import annotations

import io
import json
import math
import struct

import numpy as np
from PIL import Image
from scipy.spatial.transform import Rotation, Slerp


def quaternion(axis, degrees: float) -> list[float]:
    """A rotation of ``degrees`` about ``axis`` as glTF's (x, y, z, w)."""
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    half = math.radians(degrees) / 2
    return [*(a * math.sin(half)).tolist(), math.cos(half)]


class GltfBuilder:
    def __init__(self):
        self.gltf: dict = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": []}], "nodes": []}
        self.binary = bytearray()

    def _list(self, key: str) -> list:
        return self.gltf.setdefault(key, [])

    def _view(self, data: bytes) -> int:
        self.binary += b"\0" * (-len(self.binary) % 4)
        self._list("bufferViews").append({"buffer": 0, "byteOffset": len(self.binary), "byteLength": len(data)})
        self.binary += data
        return len(self.gltf["bufferViews"]) - 1

    def _accessor(self, array: np.ndarray, kind: str) -> int:
        component = {np.dtype(np.float32): 5126, np.dtype(np.uint32): 5125}[array.dtype]
        accessor = {
            "bufferView": self._view(array.tobytes()),
            "componentType": component,
            "count": len(array),
            "type": kind,
        }
        if kind == "VEC3" and array.dtype == np.float32:
            accessor["min"], accessor["max"] = array.min(axis=0).tolist(), array.max(axis=0).tolist()
        self._list("accessors").append(accessor)
        return len(self.gltf["accessors"]) - 1

    def _node(self, node: dict) -> int:
        self.gltf["nodes"].append(node)
        index = len(self.gltf["nodes"]) - 1
        self.gltf["scenes"][0]["nodes"].append(index)
        return index

    def texture(self, rgba: np.ndarray) -> int:
        """An embedded PNG of ``rgba`` (h, w, 4) uint8; nearest filtering is not asked: the renderer is bilinear."""
        png = io.BytesIO()
        Image.fromarray(np.asarray(rgba, np.uint8)).save(png, format="PNG")
        self._list("images").append({"bufferView": self._view(png.getvalue()), "mimeType": "image/png"})
        self._list("textures").append({"source": len(self.gltf["images"]) - 1})
        return len(self.gltf["textures"]) - 1

    def material(self, **material) -> int:
        self._list("materials").append(material)
        return len(self.gltf["materials"]) - 1

    def mesh(self, positions, indices, uv=None, colors=None, material=None, translation=None, name="mesh") -> int:
        attributes = {"POSITION": self._accessor(np.asarray(positions, np.float32), "VEC3")}
        if uv is not None:
            attributes["TEXCOORD_0"] = self._accessor(np.asarray(uv, np.float32), "VEC2")
        if colors is not None:
            attributes["COLOR_0"] = self._accessor(np.asarray(colors, np.float32), "VEC3")
        primitive = {
            "attributes": attributes,
            "indices": self._accessor(np.asarray(indices, np.uint32).ravel(), "SCALAR"),
        }
        if material is not None:
            primitive["material"] = material
        self._list("meshes").append({"name": name, "primitives": [primitive]})
        node = {"mesh": len(self.gltf["meshes"]) - 1}
        if translation is not None:
            node["translation"] = list(translation)
        return self._node(node)

    def quad(self, corners, uv=((0, 1), (1, 1), (1, 0), (0, 0)), **kwargs) -> int:
        """Two triangles over four corners, counter-clockwise seen from the front; ``uv`` glTF's (v down)."""
        return self.mesh(corners, [[0, 1, 2], [0, 2, 3]], uv=uv, **kwargs)

    def camera(self, name: str, translation, rotation=(0, 0, 0, 1), yfov_degrees: float = 50.0) -> int:
        self._list("cameras").append(
            {"name": name, "type": "perspective", "perspective": {"yfov": math.radians(yfov_degrees), "znear": 0.01}}
        )
        return self._node(
            {"camera": len(self.gltf["cameras"]) - 1, "translation": list(translation), "rotation": list(rotation)}
        )

    def light(self, name: str, kind: str, translation=(0, 0, 0), rotation=(0, 0, 0, 1)) -> int:
        lights = self.gltf.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})["lights"]
        lights.append({"name": name, "type": kind, "color": [1, 1, 1], "intensity": 3})
        self.gltf.setdefault("extensionsUsed", []).append("KHR_lights_punctual")
        return self._node(
            {
                "translation": list(translation),
                "rotation": list(rotation),
                "extensions": {"KHR_lights_punctual": {"light": len(lights) - 1}},
            }
        )

    def glb(self) -> bytes:
        gltf = dict(self.gltf, buffers=[{"byteLength": len(self.binary)}])
        text = json.dumps(gltf).encode()
        text += b" " * (-len(text) % 4)
        binary = bytes(self.binary) + b"\0" * (-len(self.binary) % 4)
        body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
        return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body

    def keys(self, values, kind: str) -> int:
        """An accessor of float keys (times as ``SCALAR``, with the min and max glTF asks of them)."""
        array = np.asarray(values, np.float32).reshape(len(values), -1)
        index = self._accessor(array if kind != "SCALAR" else array.ravel(), kind)
        if kind == "SCALAR":
            self.gltf["accessors"][index]["min"] = [float(array.min())]
            self.gltf["accessors"][index]["max"] = [float(array.max())]
        return index

    def animate(self, name: str, channels) -> None:
        """An animation of ``channels``: ``(target, path, times, values, interpolation)``, target a node index,
        or ``("camera", k)`` for camera k's ``yfov`` through ``KHR_animation_pointer``."""
        animation: dict = {"name": name, "channels": [], "samplers": []}
        for target, path, times, values, interpolation in channels:
            kind = {"translation": "VEC3", "scale": "VEC3", "rotation": "VEC4", "yfov": "SCALAR"}[path]
            sampler = {"input": self.keys(times, "SCALAR"), "output": self.keys(values, kind),
                       "interpolation": interpolation}  # fmt: skip
            animation["samplers"].append(sampler)
            if isinstance(target, tuple):
                pointer = {"KHR_animation_pointer": {"pointer": f"/cameras/{target[1]}/perspective/yfov"}}
                spec = {"path": "pointer", "extensions": pointer}
                if "KHR_animation_pointer" not in self.gltf.setdefault("extensionsUsed", []):
                    self.gltf["extensionsUsed"].append("KHR_animation_pointer")
            else:
                spec = {"node": target, "path": path}
            animation["channels"].append({"sampler": len(animation["samplers"]) - 1, "target": spec})
        self._list("animations").append(animation)


# ---- an animated camera, as Blender exports one ----

WALL = [[-3, -2, -2], [3, -2, -2], [3, 2, -2], [-3, 2, -2]]
TIMES = [0.0, 1.0, 2.5]
EYES = [[0, 0, 5], [1, 0.5, 4], [-1, 0, 3]]
TURNS = [quaternion((0, 1, 0), 0), quaternion((0, 1, 0), 20), quaternion((1, 0, 0), -15)]
FOVS = [math.radians(50), math.radians(40), math.radians(30)]
PARENT = (0.5, -0.25, 0.0)  # the camera's parent node stands here, turned 10 degrees about y
PARENT_TURN = quaternion((0, 1, 0), 10)


def animated_camera(channels=None) -> GltfBuilder:
    """A wall, a still camera "Still", and a camera "Shot" under a parent node, moved and zoomed."""
    b = GltfBuilder()
    b.quad(WALL, material=b.material(pbrMetallicRoughness={"baseColorFactor": [0.8, 0.3, 0.1, 1]}))
    b.camera("Still", (0, 0, 6))
    shot = b.camera("Shot", EYES[0], TURNS[0])
    b.gltf["scenes"][0]["nodes"].remove(shot)
    b.gltf["nodes"].append({"translation": list(PARENT), "rotation": PARENT_TURN, "children": [shot]})
    b.gltf["scenes"][0]["nodes"].append(len(b.gltf["nodes"]) - 1)
    b.animate(
        "Action",
        channels
        or [
            (shot, "translation", TIMES, EYES, "LINEAR"),
            (shot, "rotation", TIMES, TURNS, "LINEAR"),
            (("camera", 1), "yfov", TIMES, FOVS, "LINEAR"),
        ],
    )
    return b


def expected_camera(t: np.ndarray):
    """The animation's camera at ``t``, computed apart: numpy's lines, scipy's slerp, the parent's matrix."""
    eye_local = np.stack([np.interp(t, TIMES, np.asarray(EYES)[:, k]) for k in range(3)], axis=1)
    turn = Slerp(TIMES, Rotation.from_quat(TURNS))(np.clip(t, TIMES[0], TIMES[-1]))
    parent = Rotation.from_quat(PARENT_TURN)
    eye = parent.apply(eye_local) + PARENT
    forward = (parent * turn).apply([0, 0, -1])
    up = (parent * turn).apply([0, 1, 0])
    return eye, forward, up, np.degrees(np.interp(t, TIMES, FOVS))
