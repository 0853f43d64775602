"""Models to upload, built in code: a box in every kind the server reads, and hostile files of each sort."""

from __future__ import annotations

import io
import json
import struct
import zipfile
import zlib

import numpy as np
import trimesh
from PIL import Image


def box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(1.0, 1.0, 1.0))


def glb() -> bytes:
    return box().export(file_type="glb")


def obj() -> bytes:
    return box().export(file_type="obj").encode()


def ply() -> bytes:
    return box().export(file_type="ply")


def stl() -> bytes:
    return box().export(file_type="stl")


def zipped(files: dict[str, bytes]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    return out.getvalue()


def gltf_zip() -> bytes:
    """A .gltf and its .bin buffers, in a zip."""
    return zipped(trimesh.exchange.gltf.export_gltf(box()))


def png(width: int, height: int, color=(255, 0, 0)) -> bytes:
    out = io.BytesIO()
    Image.new("RGB", (width, height), color).save(out, "PNG")
    return out.getvalue()


QUAD_OBJ = b"""mtllib quad.mtl
v -1 -1 0
v 1 -1 0
v 1 1 0
v -1 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl painted
f 1/1 2/2 3/3
f 1/1 3/3 4/4
"""


def textured_obj_zip(texture: bytes | None = None, map_path: str = "textures/red.png") -> bytes:
    """A quad facing +z whose material maps a texture (pure red unless given): OBJ, MTL and PNG in a zip."""
    mtl = f"newmtl painted\nKd 1 1 1\nmap_Kd {map_path}\n".encode()
    return zipped({"quad.obj": QUAD_OBJ, "quad.mtl": mtl, "textures/red.png": texture or png(8, 8)})


# ---- hostile ----


def bomb_png(width: int, height: int) -> bytes:
    """A real decompression bomb: a PNG of ``width`` x ``height`` black pixels, a few hundred bytes per
    million pixels on disk, three bytes a pixel once decoded."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    deflate = zlib.compressobj(9)
    row = b"\0" * (1 + 3 * width)  # filter byte, then RGB
    idat = b"".join(deflate.compress(row) for _ in range(height)) + deflate.flush()
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def zip_bomb(megabytes: int) -> bytes:
    """A zip whose one OBJ inflates to ``megabytes`` MiB (of spaces, which compress a thousandfold)."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf, zf.open("bomb.obj", "w", force_zip64=True) as f:
        for _ in range(megabytes):
            f.write(b" " * (1 << 20))
    return out.getvalue()


def zip_that_lies() -> bytes:
    """A zip whose entry declares 100 bytes and inflates to a megabyte: both size fields patched."""
    data = bytearray(zipped({"box.obj": obj() + b"#" * (1 << 20)}))
    actual = struct.pack("<I", len(obj()) + (1 << 20))
    for offset in (i for i in range(len(data) - 4) if data[i : i + 4] == actual):
        data[offset : offset + 4] = struct.pack("<I", 100)
    return bytes(data)


def many_files(count: int) -> bytes:
    return zipped({"box.obj": obj(), **{f"junk/{k}.txt": b"" for k in range(count)}})


def zip_slip() -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("box.obj", obj())
        zf.writestr("../../escaped.txt", b"out of the folder")
    return out.getvalue()


def glb_with_a_lying_header() -> bytes:
    data = bytearray(glb())
    data[8:12] = struct.pack("<I", len(data) * 1000)
    return bytes(data)


def gltf_reaching_out() -> bytes:
    files = trimesh.exchange.gltf.export_gltf(box())
    gltf = json.loads(files["model.gltf"])
    gltf["buffers"][0]["uri"] = "../../../../etc/passwd"
    return zipped({**files, "model.gltf": json.dumps(gltf).encode()})


def obj_reaching_out() -> bytes:
    return b"mtllib /etc/passwd\n" + obj()


def obj_with_nan() -> bytes:
    return obj().replace(b"v -0.50000000 -0.50000000 -0.50000000", b"v nan -0.5 -0.5", 1)


def vertices_of(data: bytes) -> np.ndarray:
    return np.asarray(trimesh.load(io.BytesIO(data), file_type="glb", force="mesh").vertices)


def glb_edited(edit) -> bytes:
    """The box's GLB with its glTF JSON changed by ``edit(gltf)`` (in place), packed again."""
    data = glb()
    json_length = struct.unpack_from("<I", data, 12)[0]
    gltf = json.loads(data[20 : 20 + json_length])
    edit(gltf)
    text = json.dumps(gltf).encode()
    text += b" " * (-len(text) % 4)
    rest = data[20 + json_length :]  # the binary chunk, header and all
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + rest
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def glb_moved(**node) -> bytes:
    """The box placed by its node's own ``translation``, ``scale`` or ``matrix``."""
    return glb_edited(lambda gltf: gltf["nodes"][0].update(node))


def glb_placed_many_times(count: int, size: int = 1) -> bytes:
    """A small file that places one mesh ``count`` times, side by side, each a node of its own (a few dozen
    bytes a node); the mesh is the box, or with ``size`` a grid of ``size`` x ``size`` boxes' worth of
    triangles as declared (its accessor's count is all that is changed)."""

    def edit(gltf):
        gltf["nodes"] = [{"mesh": 0, "translation": [1.5 * k, 0, 0]} for k in range(count)]
        gltf["scenes"] = [{"nodes": list(range(count))}]
        gltf["accessors"][0]["count"] *= size * size

    return glb_edited(edit)


def far_obj() -> bytes:
    """One triangle a trillion units wide."""
    return b"v -5e11 0 0\nv 5e11 0 0\nv 0 1 0\nf 1 2 3\n"


def glb_with_cameras(count: int, **node) -> bytes:
    """The box with ``count`` camera nodes (each ``{"camera": 0, **node}``), a few bytes each: the cameras are
    many where the file is small."""

    def edit(gltf):
        gltf["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01}}]
        first = len(gltf["nodes"])
        gltf["nodes"] += [{"camera": 0, **node} for _ in range(count)]
        gltf["scenes"][0]["nodes"] += list(range(first, first + count))

    return glb_edited(edit)


def glb_with_a_camera_under(parent: dict, **node) -> bytes:
    """The box and one camera node under a ``parent`` node (its ``scale``, ``matrix``...)."""

    def edit(gltf):
        gltf["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01}}]
        gltf["nodes"] += [{"camera": 0, **node}, {**parent, "children": [len(gltf["nodes"])]}]
        gltf["scenes"][0]["nodes"].append(len(gltf["nodes"]) - 1)

    return glb_edited(edit)
