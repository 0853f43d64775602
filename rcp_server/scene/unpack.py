"""What the sandbox's child process does with an uploaded model: recognise its kind, unpack a zip within
limits, check every path and image the model names, read it with :func:`meshes.load_mesh_file`, and write
the parts as plain arrays for the parent (:mod:`rcp_server.scene.untrusted`) to check again.

:func:`job` is the child's entry point, with ``WORK/upload`` the uploaded bytes: it confines itself (address
space, CPU time, priority) before it reads a byte of them. Nothing here trusts the file: a GLB's header, a
zip's declared sizes, a glTF's or an MTL's paths and an image's header are all checked before anything is
decoded.
"""

from __future__ import annotations

import base64
import io
import json
import os
import re
import resource
import stat
import struct
import sys
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import unquote

import numpy as np

MODEL_SUFFIXES = (".glb", ".gltf", ".obj", ".ply", ".stl")
UPLOAD_SUFFIXES = (*MODEL_SUFFIXES, ".zip")
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tga", ".gif", ".webp", ".tif", ".tiff", ".dds"})
# how other kinds of file begin, to say what a file with a model's name really is
SIGNATURES = (
    (b"\x89PNG\r\n\x1a\n", "a PNG image"),
    (b"\xff\xd8\xff", "a JPEG image"),
    (b"GIF8", "a GIF image"),
    (b"RIFF", "a RIFF file (WebP, WAV or AVI)"),
    (b"PK\x03\x04", "a zip archive"),
    (b"PK\x05\x06", "an empty zip archive"),
    (b"%PDF", "a PDF document"),
    (b"\x7fELF", "a program"),
    (b"MZ", "a Windows program"),
    (b"\x1f\x8b", "a gzip archive"),
    (b"7z\xbc\xaf", "a 7-Zip archive"),
    (b"Rar!", "a RAR archive"),
    (b"glTF", "a GLB model"),
    (b"ply", "a PLY model"),
)
READER_ENVIRONMENT = ("PATH", "LANG", "LC_ALL", "LC_CTYPE", "TMPDIR", "PYTHONHASHSEED")
"""The environment variables the reader keeps: where programs and temporary files are, the text encoding.
(Its imports need no PYTHONPATH: the fork server is handed the server's ``sys.path``.)"""
NAME_MAX = 255  # bytes in one part of a path (Linux's NAME_MAX)
PATH_MAX = 1024  # bytes in a path inside the upload (Linux takes 4096 from the root; the work folder comes first)
GLB_JSON, GLB_BIN = 0x4E4F534A, 0x004E4942  # chunk types: "JSON" and "BIN\0", little-endian
_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:")  # http:, file:, and a Windows drive letter (C:) alike
_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+([^\r\n]+)", re.M)
_FACE_LINE = re.compile(rb"^[ \t]*f[ \t][^\r\n]*", re.M)
_PLY_FACES = re.compile(rb"^element[ \t]+face[ \t]+(\d+)", re.M)
_MTL_MAP = re.compile(rb"^[ \t]*(?:map_\w+|bump|disp|decal|refl|norm)[ \t]+([^\r\n]+)", re.M | re.I)


@dataclass(frozen=True)
class Limits:
    """What one upload may take. Sizes in bytes; ``memory_bytes`` is the reader's address space beyond what
    the child has mapped once its libraries are loaded; ``seconds`` wall-clock (CPU time is capped too)."""

    max_triangles: int = 2_000_000
    max_texture_pixels: int = 32 << 20  # all of a model's images together, width x height
    max_unpacked_bytes: int = 512 << 20  # a zip's files together, as unpacked
    max_files: int = 1000  # in a zip
    max_meshes: int = 4096  # separate meshes in one model (the staircase has 348)
    max_nodes: int = 16384  # nodes a glTF's scene reaches, cameras and lights among them (each is built)
    memory_bytes: int = 2 << 30
    seconds: float = 60.0
    room_bytes: int | None = None  # memory the server's uploaded scenes have left (None: no such budget)


BYTES_PER_TRIANGLE = 200
"""Memory an uploaded scene takes per triangle, at least (its arrays, the traced geometry, Embree's tree): what
the declared triangles are weighed with against ``Limits.room_bytes``."""


class Refused(ValueError):
    """An upload that cannot be used; the message is one line for the uploader, naming the fault."""


class NoRoom(Refused):
    """An upload that would not fit in the memory the uploaded scenes have left (it may, later)."""


# ---- what kind of file it is ----


def looks_like(head: bytes) -> str | None:
    """What a file's first bytes say it is ("a PNG image"), None when they say nothing known."""
    return next((what for magic, what in SIGNATURES if head.startswith(magic)), None)


def check_kind(path: Path, name: str) -> None:
    """Refuses a file whose content does not match its name's kind (``name`` says which: ``x.glb``)."""
    size = path.stat().st_size
    if size == 0:
        raise Refused(f"{name} is empty")
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    suffix = Path(name).suffix.lower()
    kind = {".glb": "a GLB model", ".ply": "a PLY model", ".zip": "a zip archive"}.get(suffix)
    seen = looks_like(head)
    if kind is not None:
        if seen != kind and not (suffix == ".zip" and seen == "an empty zip archive"):
            raise Refused(f"{name} is not {kind}: " + (f"it looks like {seen}" if seen else "its first bytes say not"))
        return
    if suffix == ".stl":
        triangles = struct.unpack_from("<I", head, 80)[0] if size >= 84 else -1
        if size == 84 + 50 * triangles:  # a binary STL: its size follows from its triangle count
            return
        if head.lstrip()[:5].lower() == b"solid" and b"\0" not in head:
            return
        raise Refused(f"{name} is not an STL model: " + (f"it looks like {seen}" if seen else "neither kind of STL"))
    # .obj and .gltf are text
    if seen is not None or b"\0" in head:
        raise Refused(f"{name} is not a text file as {suffix} is: " + (f"it looks like {seen}" if seen else "binary"))
    if suffix == ".gltf" and not head.lstrip().startswith(b"{"):
        raise Refused(f"{name} is not a glTF file: it does not hold a JSON object")


# ---- a zip, unpacked within limits ----


def safe_relative(ref: str, where: str) -> PurePosixPath:
    """A path named inside the upload (a zip entry, a glTF URI, an MTL map) as a relative path that stays in
    it; refuses absolute paths, drive letters, URLs and ``..``."""
    text = ref.strip().replace("\\", "/")
    if "\0" in text or not text:
        raise Refused(f"{where}: an empty or broken path")
    if text.startswith("/") or _SCHEME.match(text):
        raise Refused(f"{where}: the path {ref[:80]!r} points outside the upload (absolute, or a URL)")
    path = PurePosixPath(text)
    if ".." in path.parts:
        raise Refused(f"{where}: the path {ref[:80]!r} points outside the upload ('..')")
    return path


def unzip(archive: Path, folder: Path, limits: Limits) -> None:
    """Every file of ``archive`` into ``folder``, refusing links, paths leading out or that no file system
    takes, names that clash, and more files or bytes than ``limits`` allow, by the declared sizes first and by
    the bytes actually inflated as they come."""
    try:
        zf = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as exc:
        raise Refused(f"the zip cannot be read ({exc})") from None
    with zf:
        entries = [e for e in zf.infolist() if not e.is_dir()]
        if len(entries) > limits.max_files:
            raise Refused(f"the zip holds {len(entries)} files; at most {limits.max_files} are taken")
        declared = sum(e.file_size for e in entries)
        if declared > limits.max_unpacked_bytes:
            raise Refused(f"the zip unpacks to {declared:,} bytes; at most {limits.max_unpacked_bytes:,} are taken")
        paths = zip_paths(entries)
        total = 0
        for entry, relative in zip(entries, paths, strict=True):
            if stat.S_ISLNK(entry.external_attr >> 16):
                raise Refused(f"the zip entry {entry.filename[:80]!r} is a link; only plain files are taken")
            target = folder / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            written = 0
            try:
                with zf.open(entry) as source, open(target, "xb") as sink:
                    while chunk := source.read(1 << 20):
                        written += len(chunk)
                        total += len(chunk)
                        if written > entry.file_size or total > limits.max_unpacked_bytes:
                            raise Refused(
                                f"the zip entry {entry.filename[:80]!r} inflates past the size it declares"
                                if written > entry.file_size
                                else f"the zip unpacks to more than {limits.max_unpacked_bytes:,} bytes"
                            )
                        sink.write(chunk)
            except (zipfile.BadZipFile, NotImplementedError, RuntimeError, EOFError) as exc:
                raise Refused(
                    f"the zip entry {entry.filename[:80]!r} is damaged or lies about its size ({exc})"
                ) from None
            except OSError as exc:  # its strerror only: the exception's own text names the folder it was written to
                raise Refused(f"the zip entry {entry.filename[:80]!r} cannot be unpacked ({exc.strerror})") from None


def zip_paths(entries: list[zipfile.ZipInfo]) -> list[PurePosixPath]:
    """The relative path each entry unpacks to, checked as a whole before a byte is written: inside the
    upload, names a file system takes (``NAME_MAX`` bytes a part), and no two entries on one path or one
    file where another entry needs a folder."""
    paths = [safe_relative(e.filename, f"the zip entry {e.filename[:80]!r}") for e in entries]
    files: set[PurePosixPath] = set()
    for entry, path in zip(entries, paths, strict=True):
        if any(len(part.encode()) > NAME_MAX for part in path.parts) or len(str(path).encode()) > PATH_MAX:
            raise Refused(
                f"the zip entry {entry.filename[:80]!r} has a name longer than {NAME_MAX} bytes (a folder's or the "
                f"file's), or a path longer than {PATH_MAX}"
            )
        if path in files:
            raise Refused(f"the zip holds {entry.filename[:80]!r} twice")
        files.add(path)
    for entry, path in zip(entries, paths, strict=True):
        clash = next((parent for parent in path.parents if parent in files), None)
        if clash is not None:
            raise Refused(
                f"the zip holds both a file {str(clash)[:80]!r} and {entry.filename[:80]!r}, which needs a folder "
                "of that name"
            )
    return paths


def the_model(folder: Path) -> Path:
    """The one model file among the unpacked files (macOS's ``__MACOSX`` shadows ignored)."""
    found = sorted(
        p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in MODEL_SUFFIXES and "__MACOSX" not in p.parts
    )
    if not found:
        raise Refused(f"the zip holds no model ({', '.join(MODEL_SUFFIXES)})")
    if len(found) > 1:
        names = ", ".join(str(p.relative_to(folder)) for p in found[:4])
        raise Refused(f"the zip holds {len(found)} models ({names}{', ...' if len(found) > 4 else ''}): put in one")
    return found[0]


# ---- what a model names: paths that must stay inside, images that must stay small ----


def _inside(folder: Path, base: Path, ref: str, where: str) -> Path:
    """The file ``ref`` names, relative to ``base`` (a folder within ``folder``), refused unless inside."""
    relative = safe_relative(ref, where)
    path = (base / relative).resolve()
    if not path.is_relative_to(folder.resolve()):
        raise Refused(f"{where}: the path {ref[:80]!r} points outside the upload")
    return path


def glb_chunks(data: bytes, name: str) -> tuple[dict, bytes]:
    """The JSON and the binary chunk of a GLB, every length in its header checked against the bytes."""
    if len(data) < 20:
        raise Refused(f"{name}: a GLB header needs 20 bytes, the file has {len(data)}")
    magic, version, length = struct.unpack_from("<4sII", data)
    if version != 2:
        raise Refused(f"{name}: GLB version {version}; only version 2 is read")
    if length != len(data):
        raise Refused(f"{name}: the GLB header says the file has {length:,} bytes, it has {len(data):,}")
    chunks, offset = [], 12
    while offset < len(data):
        if offset + 8 > len(data):
            raise Refused(f"{name}: a GLB chunk header is cut off at byte {offset:,}")
        size, kind = struct.unpack_from("<II", data, offset)
        if offset + 8 + size > len(data):
            raise Refused(f"{name}: a GLB chunk claims {size:,} bytes, past the end of the file")
        chunks.append((kind, data[offset + 8 : offset + 8 + size]))
        offset += 8 + size
    if not chunks or chunks[0][0] != GLB_JSON:
        raise Refused(f"{name}: a GLB's first chunk must be its JSON")
    binary = next((chunk for kind, chunk in chunks[1:] if kind == GLB_BIN), b"")
    return _json(chunks[0][1], name), binary


def _json(text: bytes, name: str) -> dict:
    try:
        gltf = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise Refused(f"{name}: the glTF JSON cannot be read ({str(exc)[:80]})") from None
    if not isinstance(gltf, dict):
        raise Refused(f"{name}: the glTF JSON is not an object")
    return gltf


def _items(gltf: dict, key: str, name: str) -> list[dict]:
    items = gltf.get(key) or []
    if not isinstance(items, list) or not all(isinstance(item, dict) for item in items):
        raise Refused(f"{name}: the glTF's {key!r} is not a list of objects")
    return items


def gltf_images(gltf: dict, binary: bytes, model: Path, folder: Path, name: str) -> list[tuple[str, bytes]]:
    """Checks every buffer and image URI of a glTF (data, or a file inside the upload that exists, for
    buffers) and returns the images stored inside the model itself: (label, encoded bytes)."""
    buffers = []
    for index, buffer in enumerate(_items(gltf, "buffers", name)):
        uri = buffer.get("uri")
        if uri is None:
            buffers.append(binary)  # the GLB's own binary chunk
        elif not isinstance(uri, str):
            raise Refused(f"{name}: buffer {index} has a URI that is not text")
        elif "base64," in uri:
            buffers.append(_data_uri(uri, f"{name}: buffer {index}"))
        else:
            path = _inside(folder, model.parent, unquote(uri), f"{name}: buffer {index}")
            _inside(folder, model.parent, uri, f"{name}: buffer {index}")
            if not path.is_file():
                raise Refused(f"{name}: buffer {index} is the file {uri[:80]!r}, which is not in the upload")
            buffers.append(path.read_bytes())
    views = _items(gltf, "bufferViews", name)
    embedded = []
    for index, image in enumerate(_items(gltf, "images", name)):
        label = f"{name}: image {index}"
        uri = image.get("uri")
        if isinstance(uri, str) and "base64," in uri:
            embedded.append((label, _data_uri(uri, label)))
        elif isinstance(uri, str):
            _inside(folder, model.parent, unquote(uri), label)
            _inside(folder, model.parent, uri, label)
        elif isinstance(image.get("bufferView"), int):
            view: dict | None = views[image["bufferView"]] if 0 <= image["bufferView"] < len(views) else None
            held = view.get("buffer") if view else None
            if view is None or not isinstance(held, int) or not 0 <= held < len(buffers):
                raise Refused(f"{label}: its bufferView does not exist")
            start, length = view.get("byteOffset", 0), view.get("byteLength")
            if not isinstance(start, int) or not isinstance(length, int) or start < 0 or length < 0:
                raise Refused(f"{label}: its bufferView has no valid byteOffset and byteLength")
            if start + length > len(buffers[held]):
                raise Refused(f"{label}: its bufferView reaches past the end of its buffer")
            embedded.append((label, buffers[held][start : start + length]))
    return embedded


def gltf_declared(gltf: dict, name: str) -> tuple[int, int, int]:
    """Triangles and mesh instances a glTF declares, as its default scene's nodes place its meshes (a mesh
    that a thousand nodes place counts a thousand times), and the nodes its scene reaches: counted from the
    accessors' counts and the node tree alone, before a byte of geometry is read. Broken references count
    nothing (the reader refuses them later)."""
    accessors, meshes = _items(gltf, "accessors", name), _items(gltf, "meshes", name)
    nodes = _items(gltf, "nodes", name)

    def count(index) -> int:
        ok = isinstance(index, int) and 0 <= index < len(accessors) and isinstance(accessors[index].get("count"), int)
        return max(accessors[index]["count"], 0) if ok else 0

    def mesh_triangles(index) -> int:
        if not isinstance(index, int) or not 0 <= index < len(meshes):
            return 0
        triangles = 0
        for primitive in meshes[index].get("primitives") or []:
            if not isinstance(primitive, dict):
                continue
            attributes = primitive.get("attributes")
            corners = count(primitive["indices"]) if "indices" in primitive else None
            if corners is None:
                corners = count(attributes.get("POSITION")) if isinstance(attributes, dict) else 0
            mode = primitive.get("mode", 4)
            triangles += corners // 3 if mode == 4 else max(corners - 2, 0) if mode in (5, 6) else 0
        return triangles

    scenes = _items(gltf, "scenes", name)
    if scenes:
        chosen = gltf.get("scene", 0)
        scene = scenes[chosen] if isinstance(chosen, int) and 0 <= chosen < len(scenes) else scenes[0]
        roots = _node_list(scene.get("nodes"), len(nodes))
    else:  # no scene: every node nobody holds
        held = {c for node in nodes for c in _node_list(node.get("children"), len(nodes))}
        roots = [k for k in range(len(nodes)) if k not in held]
    # every node the scene reaches, once (a node held twice, or holding itself, is read once)
    reached, waiting = set(), list(roots)
    while waiting:
        index = waiting.pop()
        if index not in reached:
            reached.add(index)
            waiting.extend(_node_list(nodes[index].get("children"), len(nodes)))
    triangles = instances = 0
    for index in reached:
        node = nodes[index]
        if "mesh" not in node:
            continue
        copies = 1  # or as many as EXT_mesh_gpu_instancing's attributes give
        extensions = node.get("extensions")
        instancing = extensions.get("EXT_mesh_gpu_instancing") if isinstance(extensions, dict) else None
        if isinstance(instancing, dict) and isinstance(instancing.get("attributes"), dict):
            copies = max([count(a) for a in instancing["attributes"].values()] or [1])
        triangles += copies * mesh_triangles(node["mesh"])
        instances += copies
    return triangles, instances, len(reached)


def _node_list(value, length: int) -> list[int]:
    """The valid node indices of a glTF list of them (a scene's ``nodes``, a node's ``children``)."""
    return [k for k in value if isinstance(k, int) and 0 <= k < length] if isinstance(value, list) else []


def declared_triangles(model: Path) -> int | None:
    """Triangles (at least) that an OBJ, PLY or binary STL says it has, from its text or header alone; None
    for kinds that declare nothing cheaply (an ASCII STL)."""
    suffix = model.suffix.lower()
    if suffix == ".obj":
        return sum(len(line.split()) - 3 for line in _FACE_LINE.findall(model.read_bytes()))
    with open(model, "rb") as f:
        head = f.read(1 << 16)
    if suffix == ".ply":
        found = _PLY_FACES.search(head.split(b"end_header", 1)[0])
        return int(found.group(1)) if found else None
    if suffix == ".stl" and not head.lstrip()[:5].lower() == b"solid" and len(head) >= 84:
        return struct.unpack_from("<I", head, 80)[0]
    return None


def _data_uri(uri: str, where: str) -> bytes:
    try:
        return base64.b64decode(uri[uri.index("base64,") + 7 :], validate=False)
    except ValueError:
        raise Refused(f"{where}: its data URI is not base64") from None


def obj_paths(model: Path, folder: Path) -> None:
    """Checks the material libraries an OBJ names and the texture maps of every MTL in the upload."""
    name = model.name
    for match in _MTLLIB.finditer(model.read_bytes()):
        ref = match.group(1).decode("utf-8", "replace")
        for each in {ref, *ref.split()}:
            _inside(folder, model.parent, each, f"{name}: mtllib")
    for mtl in folder.rglob("*"):
        if mtl.suffix.lower() != ".mtl" or not mtl.is_file():
            continue
        for match in _MTL_MAP.finditer(mtl.read_bytes()):
            ref = match.group(1).decode("utf-8", "replace").strip()
            for each in {ref, ref.split()[-1]}:  # options come first ("-bm 0.5 bump.png"): the name is last
                _inside(folder, mtl.parent, each, f"{mtl.name}: texture map")


def image_pixels(data: bytes | Path, label: str, limits: Limits) -> int:
    """An image's width x height from its header alone (nothing decoded), refused past the limit."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(data if isinstance(data, Path) else io.BytesIO(data)) as image:
            width, height = image.size
    except (OSError, UnidentifiedImageError, ValueError, Image.DecompressionBombError, SyntaxError) as exc:
        if isinstance(exc, Image.DecompressionBombError):
            raise Refused(f"{label}: the image is larger than {limits.max_texture_pixels:,} pixels") from None
        raise Refused(f"{label}: not an image that can be read ({type(exc).__name__})") from None
    if width * height > limits.max_texture_pixels:
        raise Refused(
            f"{label}: a {width}x{height} image is more than the {limits.max_texture_pixels:,} pixels "
            "a model's textures may have"
        )
    return width * height


def check_model(model: Path, folder: Path, limits: Limits) -> None:
    """Every check before the model is read: its kind, its header (GLB), the triangles and mesh instances it
    declares, the paths it names and its images (their pixels from their headers)."""
    name = model.name
    check_kind(model, name)
    embedded: list[tuple[str, bytes]] = []
    suffix = model.suffix.lower()
    instances: int | None = None
    nodes = 0
    triangles: int | None
    if suffix in (".glb", ".gltf"):
        gltf, binary = (
            glb_chunks(model.read_bytes(), name) if suffix == ".glb" else (_json(model.read_bytes(), name), b"")
        )
        embedded = gltf_images(gltf, binary, model, folder, name)
        triangles, instances, nodes = gltf_declared(gltf, name)
    else:
        triangles = declared_triangles(model)
    if suffix == ".obj":
        obj_paths(model, folder)
    # what the model would unfold into, refused before anything is built
    if triangles is not None and triangles > limits.max_triangles:
        raise Refused(
            f"{name} declares {triangles:,} triangles (as placed); at most {limits.max_triangles:,} are taken"
        )
    if instances is not None and instances > limits.max_meshes:
        raise Refused(f"{name} places meshes {instances:,} times; at most {limits.max_meshes:,} are taken")
    if nodes > limits.max_nodes:  # 60,000 camera nodes in 300 KB took the reader seconds, for nothing drawn
        raise Refused(f"{name}'s scene has {nodes:,} nodes; at most {limits.max_nodes:,} are taken")
    if triangles is not None and limits.room_bytes is not None and triangles * BYTES_PER_TRIANGLE > limits.room_bytes:
        raise NoRoom(
            f"{name} declares {triangles:,} triangles, {triangles * BYTES_PER_TRIANGLE >> 20} MiB or more once built, "
            f"and the uploaded scenes have {limits.room_bytes >> 20} MiB left; try again later, or a smaller model"
        )
    pixels = sum(image_pixels(data, label, limits) for label, data in embedded)
    for path in sorted(folder.rglob("*")):
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file() and "__MACOSX" not in path.parts:
            pixels += image_pixels(path, str(path.relative_to(folder)), limits)
    if pixels > limits.max_texture_pixels:
        raise Refused(f"the model's images have {pixels:,} pixels; at most {limits.max_texture_pixels:,} are taken")


# ---- reading, and the arrays handed back ----


def read_upload(upload: Path, filename: str, folder: Path, limits: Limits):
    """The model of an uploaded file (``filename`` gives its kind), unpacked and checked in ``folder``.

    Returns a :class:`meshes.Model` (its parts, a glTF's cameras and lights); raises :class:`Refused` with
    the reason.
    """
    from .meshes import MeshError, load_model

    suffix = Path(filename).suffix.lower()
    if suffix not in UPLOAD_SUFFIXES:
        raise Refused(f"{filename[:80]}: not a kind of model this server reads ({', '.join(UPLOAD_SUFFIXES)})")
    folder.mkdir(parents=True, exist_ok=True)
    if suffix == ".zip":
        check_kind(upload, filename)
        unzip(upload, folder, limits)
        model = the_model(folder)
    else:
        # the uploader's name, tamed (messages name the file as they know it)
        model = folder / ((re.sub(r"[^A-Za-z0-9._-]", "_", Path(filename).stem)[:80].lstrip(".") or "model") + suffix)
        os.link(upload, model)  # both in the child's work folder: a second name, not a copy
    check_model(model, folder, limits)
    os.chdir(model.parent)  # messages name the model as the uploader knows it, not where it lies here
    try:
        loaded = load_model(Path(model.name), refuse_nonfinite=True)
    except MeshError as exc:
        if isinstance(exc.__context__, MemoryError):  # trimesh ran into the address-space limit
            raise MemoryError from None
        raise Refused(str(exc)) from None
    parts = loaded.parts
    triangles = sum(len(p.faces) for p in parts)
    if triangles > limits.max_triangles:
        raise Refused(f"the model has {triangles:,} triangles; at most {limits.max_triangles:,} are taken")
    if len(parts) > limits.max_meshes:
        raise Refused(f"the model has {len(parts):,} separate meshes; at most {limits.max_meshes:,} are taken")
    return loaded


def write_parts(path: Path, model) -> None:
    """A model (``meshes.Model``) as plain arrays in an ``.npz`` (no pickles): per part ``k`` its
    ``vertices_k`` (V, 3) float64, ``faces_k`` (F, 3) int64, ``colors_k`` (F, 3, 3) float32, ``colored_k``
    (), ``texture_k`` () int64 index or -1 and ``uv_k`` (F, 3, 2) float32 when textured or glowing through
    a texture, and its material as ``material_k`` (5,) float64 (emission r, g, b, unlit, alpha cutoff) and
    ``emission_texture_k`` () int64 index or -1, ``alpha_k`` () int64 index of its coverage or -1; each
    distinct texture once as ``image_j`` (h, w, 3) uint8, each distinct coverage as ``coverage_j`` (h, w) uint8;
    the file's cameras as ``viewpoints`` (n, 10) float64 (eye, forward, up, fov) with ``viewpoint_names``,
    its lights as ``lights`` (n, 6) float64 (position, direction) with ``light_kinds`` and ``light_names``, its
    animated cameras as ``camera_motions``, () text: their JSON (``motion.CameraMotion.to_json``)."""
    parts = model.parts
    arrays: dict[str, Any] = {"parts": np.int64(len(parts))}  # arrays and numpy scalars, by name
    images: dict[int, int] = {}
    coverages: dict[int, int] = {}

    def image_index(image) -> int:
        if id(image) not in images:
            images[id(image)] = len(images)
            arrays[f"image_{len(images) - 1}"] = image
        return images[id(image)]

    for k, part in enumerate(parts):
        arrays[f"vertices_{k}"] = part.vertices
        arrays[f"faces_{k}"] = part.faces
        arrays[f"colors_{k}"] = part.corner_colors
        arrays[f"colored_{k}"] = np.bool_(part.colored)
        texture = emission = -1
        if part.corner_uv is not None:
            if part.texture is not None:
                texture = image_index(part.texture)
            if part.material.emission_texture is not None:
                emission = image_index(part.material.emission_texture)
            if texture >= 0 or emission >= 0:
                arrays[f"uv_{k}"] = part.corner_uv
        arrays[f"texture_{k}"] = np.int64(texture)
        arrays[f"emission_texture_{k}"] = np.int64(emission)
        alpha = -1
        if texture >= 0 and part.material.alpha_texture is not None:
            if id(part.material.alpha_texture) not in coverages:
                coverages[id(part.material.alpha_texture)] = len(coverages)
                arrays[f"coverage_{len(coverages) - 1}"] = part.material.alpha_texture
            alpha = coverages[id(part.material.alpha_texture)]
        arrays[f"alpha_{k}"] = np.int64(alpha)
        m = part.material
        arrays[f"material_{k}"] = np.array([*m.emission, float(m.unlit), m.alpha_cutoff], np.float64)
    arrays["images"] = np.int64(len(images))
    arrays["coverages"] = np.int64(len(coverages))
    arrays["viewpoints"] = np.array([[*v.eye, *v.forward, *v.up, v.fov] for v in model.viewpoints], np.float64).reshape(
        -1, 10
    )
    arrays["viewpoint_names"] = np.array([v.name[:80] for v in model.viewpoints], dtype=np.str_).reshape(-1)
    arrays["lights"] = np.array([[*light.position, *light.direction] for light in model.lights], np.float64).reshape(
        -1, 6
    )
    arrays["light_kinds"] = np.array([light.kind for light in model.lights], dtype=np.str_).reshape(-1)
    arrays["light_names"] = np.array([light.name[:80] for light in model.lights], dtype=np.str_).reshape(-1)
    arrays["camera_motions"] = np.array(json.dumps([motion.to_json() for motion in model.motions]), dtype=np.str_)
    np.savez(path, **arrays)


# ---- the child's confinement and entry point ----


def _mapped_bytes() -> int:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def confine(limits: Limits) -> None:
    """Limits this process: address space (beyond what is mapped now), CPU seconds, and a low priority, so
    the server's paintings keep their cores."""
    resource.setrlimit(resource.RLIMIT_AS, (_mapped_bytes() + limits.memory_bytes,) * 2)
    seconds = int(limits.seconds) + 2
    resource.setrlimit(resource.RLIMIT_CPU, (seconds, seconds))
    os.nice(15)


def job(work: Path, filename: str, limits: Limits) -> None:
    """The child's whole life (forked from :mod:`rcp_server.scene.untrusted`'s warm fork server): confine, read,
    answer. Exit status 0 with ``work/parts.npz``; 2 (refused), 3 (over its memory) or 4 (no room left,
    :class:`NoRoom`) with ``work/refused``."""
    sys.exit(_answer(work, filename, limits))


def _answer(work: Path, filename: str, limits: Limits) -> int:
    from PIL import Image

    for key in os.environ.keys() - set(READER_ENVIRONMENT):  # the fork server's already are (untrusted._forks)
        del os.environ[key]
    confine(limits)
    # a backstop behind check_model's headers: Pillow refuses to decode more pixels than this
    Image.MAX_IMAGE_PIXELS = limits.max_texture_pixels
    warnings.simplefilter("error", Image.DecompressionBombWarning)
    try:
        model = read_upload(work / "upload", filename, work / "files", limits)
        write_parts(work / "parts.npz", model)
        return 0
    except NoRoom as exc:
        message, status = str(exc), 4
    except Refused as exc:
        message, status = str(exc), 2
    except MemoryError:
        message, status = f"reading the model needs more than the {limits.memory_bytes >> 20} MiB it may take", 3
    except Exception as exc:  # a fault the checks did not foresee, in trimesh or here: still only this file's
        message, status = f"the model cannot be read ({type(exc).__name__}: {exc})", 2
    # the uploader is told about their files, never where the server keeps them
    for folder in (work / "files", work):
        for spelling in {str(folder), str(folder.resolve())}:
            message = message.replace(spelling + "/", "").replace(spelling, "the upload")
    (work / "refused").write_text(" ".join(message.split())[:240], encoding="utf-8")
    return status
