"""Models from strangers, read in a sandbox: a child process with limits on its memory, CPU time and
wall-clock time (:func:`unpack.job`) does every check and all the parsing, and hands back plain arrays, which
are checked once more here (shapes, indices in range, finite numbers, the limits) before they become parts.
Whatever the file does, the caller gets parts or a :class:`Refused` with one line saying why.

Each child is forked from a fork server that has loaded trimesh and Pillow once (multiprocessing's
``forkserver``): a fresh process per upload, with nothing of the server's in it, in milliseconds rather than
the second and a half a new interpreter takes to import them. The fork server starts with only the
environment variables of :data:`READER_ENVIRONMENT` (not the server's token, nor anything else of its
environment), and its children inherit that.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.forkserver
import os
import threading
from pathlib import Path

import numpy as np

from . import unpack
from .gltf import MAX_LIGHTS, MAX_VIEWPOINTS, PunctualLight, Viewpoint, triple
from .meshes import PLAIN, Material, Model, Part, packed
from .motion import CameraMotion, MotionError, motions_from_json
from .unpack import READER_ENVIRONMENT, UPLOAD_SUFFIXES, Limits, NoRoom, Refused, check_kind

__all__ = ["UPLOAD_SUFFIXES", "Limits", "NoRoom", "Refused", "read_model"]

_lock = threading.Lock()
_context = None


def _forks():
    """The fork server's context, its server started on first use (once per process) with only
    :data:`READER_ENVIRONMENT`. (Should it die, multiprocessing starts another with the whole environment;
    :func:`unpack.job` keeps only those variables in each child all the same.)"""
    global _context
    with _lock:
        if _context is None:
            context = multiprocessing.get_context("forkserver")
            context.set_forkserver_preload(
                ["rcp_server.scene.unpack", "rcp_server.scene.meshes", "PIL.Image", "PIL.PngImagePlugin"]
            )
            with _environment_of_the_reader():
                multiprocessing.forkserver.ensure_running()
            _context = context
        return _context


@contextlib.contextmanager
def _environment_of_the_reader():
    """``os.environ`` reduced to :data:`READER_ENVIRONMENT` while the fork server starts (once: the server's
    threads read no variables after their start)."""
    whole = dict(os.environ)
    try:
        for key in whole.keys() - set(READER_ENVIRONMENT):
            del os.environ[key]
        yield
    finally:
        os.environ.update(whole)


def read_model(work: Path, filename: str, limits: Limits) -> Model:
    """The model (its parts, a glTF's cameras and lights) whose bytes are ``work/upload``; ``filename`` (as
    the uploader named it) gives its kind. Blocking, for seconds: run it in a worker thread. ``work`` is a
    folder of its own that the caller removes afterwards (the child unpacks there)."""
    suffix = Path(filename).suffix.lower()
    if suffix not in UPLOAD_SUFFIXES:
        raise Refused(f"{filename[:80]!r} is not a kind of file this server reads ({', '.join(UPLOAD_SUFFIXES)})")
    check_kind(work / "upload", Path(filename).name[:80])  # first bytes only: an empty file, or a PNG named .glb
    child = _forks().Process(target=unpack.job, args=(work, filename, limits), name="rcp-upload-reader", daemon=True)
    child.start()
    child.join(limits.seconds)
    if child.is_alive():
        child.kill()
        child.join()
        raise Refused(f"reading the model took longer than the {limits.seconds:g} s it may take")
    refused = work / "refused"
    if child.exitcode in (2, 3, 4) and refused.is_file():
        message = refused.read_text(encoding="utf-8", errors="replace")[:300]
        raise NoRoom(message) if child.exitcode == 4 else Refused(message)
    if child.exitcode != 0:
        how = f"signal {-child.exitcode}" if child.exitcode < 0 else f"status {child.exitcode}"
        raise Refused(f"the model could not be read: its reader stopped ({how}), most likely over a limit")
    return parts_from_arrays(work / "parts.npz", limits)


def parts_from_arrays(path: Path, limits: Limits) -> Model:
    """The child's ``.npz`` (:func:`unpack.write_parts`) as a model (:func:`model_of_arrays`)."""
    try:
        with np.load(path, allow_pickle=False) as arrays:
            found = dict(arrays.items())
    except (OSError, ValueError, KeyError) as exc:
        raise Refused(f"the model's reader handed back something unusable ({type(exc).__name__})") from None
    return model_of_arrays(found, limits)


def model_of_arrays(found: dict[str, np.ndarray], limits: Limits) -> Model:
    """The arrays of :func:`unpack.write_parts` as a model, every array checked: dtypes, shapes, face indices
    within the vertices, finite numbers, colors in [0, 1], and the limits."""
    try:
        return Model(packed(_parts(found, limits)), *_cameras_and_lights(found), _motions(found))
    except MotionError as exc:
        raise Refused(f"the model's camera animation: {exc}") from None
    except (OSError, ValueError, KeyError) as exc:
        raise Refused(f"the model's reader handed back something unusable ({type(exc).__name__})") from None


def _array(arrays: dict, key: str, dtype, shape: tuple) -> np.ndarray:
    """``arrays[key]`` of ``dtype`` whose shape matches ``shape`` (None: any length)."""
    a = arrays[key]
    fits = a.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, a.shape, strict=True))
    if a.dtype != dtype or not fits:
        raise ValueError(f"{key}: {a.dtype}{a.shape}")
    return a


def _parts(arrays: dict, limits: Limits) -> list[Part]:
    """The model's parts from the reader's arrays, each checked (a bad one is refused in one line)."""
    count = int(_array(arrays, "images", np.int64, ()))
    textures = [_array(arrays, f"image_{j}", np.uint8, (None, None, 3)) for j in range(count)]  # as shading reads them
    coverages = [
        _array(arrays, f"coverage_{j}", np.uint8, (None, None))
        for j in range(int(_array(arrays, "coverages", np.int64, ())))
    ]
    if sum(im.shape[0] * im.shape[1] for im in textures) > limits.max_texture_pixels:
        raise Refused(f"the model's images have more than {limits.max_texture_pixels:,} pixels")
    count = int(_array(arrays, "parts", np.int64, ()))
    if not 1 <= count <= limits.max_meshes:
        raise Refused(f"the model has {count:,} meshes; from 1 to {limits.max_meshes:,} are taken")
    parts = [_part(arrays, k, textures, coverages) for k in range(count)]
    triangles = sum(len(part.faces) for part in parts)
    if triangles > limits.max_triangles:
        raise Refused(f"the model has {triangles:,} triangles; at most {limits.max_triangles:,} are taken")
    return parts


def _part(arrays: dict, k: int, textures: list[np.ndarray], coverages: list[np.ndarray]) -> Part:
    """Part ``k`` of the reader's arrays, checked."""
    vertices = _array(arrays, f"vertices_{k}", np.float64, (None, 3))
    faces = _array(arrays, f"faces_{k}", np.int64, (None, 3))
    colors = _array(arrays, f"colors_{k}", np.float32, (len(faces), 3, 3))
    texture = int(_array(arrays, f"texture_{k}", np.int64, ()))
    if not np.isfinite(vertices).all():
        raise Refused("the model has vertices that are not finite numbers (NaN or infinity)")
    if len(faces) == 0 or faces.min() < 0 or faces.max() >= len(vertices):
        raise Refused("the model has triangles whose corners are not among its vertices")
    if not np.isfinite(colors).all():
        raise Refused("the model has colors that are not finite numbers")
    uv = None
    if texture >= 0:
        if texture >= len(textures):
            raise ValueError(f"texture_{k}: {texture} of {len(textures)}")
        uv = np.nan_to_num(_array(arrays, f"uv_{k}", np.float32, (len(faces), 3, 2)), nan=0.0, posinf=0.0, neginf=0.0)
    emission = int(_array(arrays, f"emission_texture_{k}", np.int64, ()))
    if emission >= len(textures) or (emission >= 0 and uv is None):
        if uv is None and 0 <= emission < len(textures):
            uv = np.nan_to_num(
                _array(arrays, f"uv_{k}", np.float32, (len(faces), 3, 2)), nan=0.0, posinf=0.0, neginf=0.0
            )
        else:
            raise ValueError(f"emission_texture_{k}: {emission} of {len(textures)}")
    m = _array(arrays, f"material_{k}", np.float64, (5,))
    alpha = int(_array(arrays, f"alpha_{k}", np.int64, ()))
    if alpha >= len(coverages) or (
        alpha >= 0 and (texture < 0 or coverages[alpha].shape != textures[texture].shape[:2])
    ):
        raise ValueError(f"alpha_{k}: {alpha} of {len(coverages)}")
    if not np.isfinite(m).all():
        raise Refused("the model has material values that are not finite numbers")
    material = Material(
        triple(np.clip(m[:3], 0.0, 1.0)),
        textures[emission] if emission >= 0 else None,
        bool(m[3]),
        float(np.clip(m[4], 0.0, 1e6)) if alpha >= 0 else 0.0,
        coverages[alpha] if alpha >= 0 else None,
    )
    colored = bool(_array(arrays, f"colored_{k}", np.bool_, ()))
    return Part(
        vertices,
        faces,
        np.clip(colors, 0.0, 1.0),
        uv,
        textures[texture] if texture >= 0 else None,
        colored,
        PLAIN if material.plain else material,
    )


def _motions(arrays: dict) -> list[CameraMotion]:
    """The animated cameras of the child's arrays (none in arrays written before they were kept), checked again
    (``motion.motions_from_json``: the limits, finite keys), at most :data:`MAX_VIEWPOINTS`."""
    if "camera_motions" not in arrays:
        return []
    text = _array(arrays, "camera_motions", arrays["camera_motions"].dtype, ())
    if text.dtype.kind != "U":
        raise ValueError("camera motions are not text")
    return motions_from_json(str(text))[:MAX_VIEWPOINTS]


def _cameras_and_lights(arrays: dict) -> tuple[list[Viewpoint], list[PunctualLight]]:
    """The glTF's cameras and lights of the child's arrays, each checked (finite, unit directions, a fov)."""
    views = _array(arrays, "viewpoints", np.float64, (None, 10))[:MAX_VIEWPOINTS]  # the reader's bound, again
    names = _array(arrays, "viewpoint_names", arrays["viewpoint_names"].dtype, (None,))[:MAX_VIEWPOINTS]
    lights = _array(arrays, "lights", np.float64, (None, 6))[:MAX_LIGHTS]
    kinds = _array(arrays, "light_kinds", arrays["light_kinds"].dtype, (None,))[:MAX_LIGHTS]
    light_names = _array(arrays, "light_names", arrays["light_names"].dtype, (None,))[:MAX_LIGHTS]
    if not (len(names) == len(views) and len(kinds) == len(light_names) == len(lights)):
        raise ValueError("cameras or lights without their names")
    if names.dtype.kind != "U" or kinds.dtype.kind != "U" or light_names.dtype.kind != "U":
        raise ValueError("names are not text")
    if not (np.isfinite(views).all() and np.isfinite(lights).all()):
        raise Refused("the model's cameras or lights hold numbers that are not finite")
    viewpoints = [
        Viewpoint(str(name)[:80], triple(v[:3]), triple(v[3:6]), triple(v[6:9]), float(v[9]))
        for name, v in zip(names, views, strict=True)
        if 0 < v[9] < 180 and np.linalg.norm(v[3:6]) > 0.5 and np.linalg.norm(v[6:9]) > 0.5
    ]
    found = [
        PunctualLight(str(name)[:80], str(kind), triple(v[:3]), triple(v[3:6]))
        for name, kind, v in zip(light_names, kinds, lights, strict=True)
        if kind in ("directional", "point", "spot")
    ]
    return viewpoints, found
