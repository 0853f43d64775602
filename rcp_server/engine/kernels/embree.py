"""The only module that talks to Embree: it owns the native scene and casts rays.

The scene is built through Embree's C API, in the library that the ``embreex`` wheel ships, so that compiled
kernels can query it from inside their loops (:class:`Embree`, :func:`intersect_rays`): rays are made,
traced and shaded in one pass, without crossing back into Python. Coherent rays go to Embree eight at a time
(``rtcIntersect8`` with ``RTC_RAY_QUERY_FLAG_COHERENT``: 2.2-2.4x ``rtcIntersect1`` on primary rays on our
AVX2 machines; ``rtcIntersect16`` is emulated there and slower). ``embreex`` itself remains for what
``rcp bench speed`` compares with: :class:`EmbreexScene`, its one-ray-at-a-time query.

The numbers below are Embree 4.4's (``include/embree4/rtcore_*.h``): the packet structs are laid out as
arrays of eight per field, and want 32-byte alignment, which the release library does not check.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from ...camera.camera import RAY_DTYPE
from .triangle import place_hits


class Hits(NamedTuple):
    """Closest hits of n rays (a named tuple: ``kernels.shade`` takes it as it is).

    face : (n,) int32, -1 on a miss;  t : (n,) float32 distance along the (unit) direction, meaningless on
    a miss;  b1, b2 : (n,) float32 barycentric weights of the face's second and third corner
    """

    face: np.ndarray
    t: np.ndarray
    b1: np.ndarray
    b2: np.ndarray

    @classmethod
    def misses(cls, n: int) -> Hits:
        zeros = np.zeros(n, np.float32)
        return cls(np.full(n, -1, np.int32), np.full(n, np.inf, np.float32), zeros, zeros.copy())

    @classmethod
    def empty(cls, n: int) -> Hits:
        """n hits to be written."""
        return cls(*(np.empty(n, a.dtype) for a in cls.misses(0)))


# ---- the library ----------------------------------------------------------------------------------------

_SCENE_FLAG_ROBUST = 1 << 2  # as embreex builds its scenes: no ray slips between two triangles' shared edge
_GEOMETRY_TRIANGLE = 0
_BUFFER_INDEX, _BUFFER_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_QUERY_COHERENT = 1 << 16
_FEATURES_ALL = 0xFFFFFFFF
_INVALID_ID = 0xFFFFFFFF


class EmbreeMissing(RuntimeError):
    """The Embree library cannot be found or loaded."""


LIBRARY_VARIABLE = "RCP_EMBREE_LIBRARY"  # an Embree 4 library to use instead of the one embreex ships


def _library_path() -> str:
    """``RCP_EMBREE_LIBRARY`` when set; else the Embree 4 library that embreex's wheel ships (its file name
    carries a hash that changes between releases); else one installed on the system."""
    given = os.environ.get(LIBRARY_VARIABLE)
    if given:
        return given
    try:
        import embreex

        libs = Path(embreex.__file__).resolve().parent.parent / "embreex.libs"
        shipped = sorted(libs.glob("libembree4*.so*")) + sorted(libs.glob("embree4*.dll"))
        if shipped:
            return str(shipped[0])
    except ImportError:
        pass
    found = ctypes.util.find_library("embree4")
    if found is None:
        raise EmbreeMissing("cannot find the Embree 4 library: install embreex (pip install embreex)")
    return found


@functools.cache
def _library() -> ctypes.CDLL:
    path = _library_path()
    try:
        lib = ctypes.CDLL(path)
    except OSError as error:
        raise EmbreeMissing(f"cannot load the Embree 4 library {path}: {str(error).splitlines()[0]}") from None
    void_p, uint = ctypes.c_void_p, ctypes.c_uint
    signatures = {
        "rtcNewDevice": (void_p, [ctypes.c_char_p]),
        "rtcGetDeviceError": (ctypes.c_int, [void_p]),
        "rtcGetDeviceLastErrorMessage": (ctypes.c_char_p, [void_p]),
        "rtcNewScene": (void_p, [void_p]),
        "rtcSetSceneFlags": (None, [void_p, ctypes.c_int]),
        "rtcCommitScene": (None, [void_p]),
        "rtcReleaseScene": (None, [void_p]),
        "rtcNewGeometry": (void_p, [void_p, ctypes.c_int]),
        "rtcSetNewGeometryBuffer": (
            void_p,
            [void_p, ctypes.c_int, uint, ctypes.c_int, ctypes.c_size_t, ctypes.c_size_t],
        ),
        "rtcCommitGeometry": (None, [void_p]),
        "rtcAttachGeometry": (uint, [void_p, void_p]),
        "rtcReleaseGeometry": (None, [void_p]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(lib, name)
        function.restype, function.argtypes = restype, argtypes
    return lib


@functools.cache
def _device() -> int:
    """One Embree device for the process (it owns the threads that build BVHs)."""
    lib = _library()
    device = lib.rtcNewDevice(None)
    if not device:
        raise EmbreeMissing("Embree could not create a device on this machine")
    return device


def _check(device: int, doing: str) -> None:
    lib = _library()
    code = lib.rtcGetDeviceError(device)
    if code:
        message = (lib.rtcGetDeviceLastErrorMessage(device) or b"").decode(errors="replace")
        raise RuntimeError(f"Embree failed {doing}: error {code}: {message}")


def _address(name: str) -> int:
    address = ctypes.cast(getattr(_library(), name), ctypes.c_void_p).value
    if not address:  # a function the library exports is never at address 0 (None, for ctypes)
        raise EmbreeMissing(f"Embree's library has no {name}")
    return address


# ---- calling Embree from compiled kernels --------------------------------------------------------------


class Embree(NamedTuple):
    """What a compiled kernel needs to query one committed scene: addresses, passed as plain integers (numba
    caches a kernel that takes a function's address as an argument, not one that refers to a ctypes function).
    Valid while the :class:`Tracer` that made it lives."""

    scene: int  # RTCScene
    intersect1: int  # rtcIntersect1
    intersect8: int  # rtcIntersect8


@intrinsic
def _call(typingctx, function, a, b, c, d):
    """Call the C function at address ``function`` with four pointer arguments given as integers (no result).
    rtcIntersect1 takes three: its fourth is ignored by the C calling convention."""
    signature = types.void(types.intp, types.intp, types.intp, types.intp, types.intp)

    def codegen(context, builder, sig, args):
        pointer = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [pointer] * 4)
        callee = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(callee, [builder.inttoptr(arg, pointer) for arg in args[1:]])
        return context.get_dummy_value()

    return signature, codegen


# RTCRayHit8, in 32-bit words of eight lanes each: the ray's fields, then the hit's (one instance level)
_ORG, _TNEAR, _DIR, _TIME, _TFAR, _MASK, _ID, _FLAGS = 0, 3, 4, 7, 8, 9, 10, 11
_NG, _U, _V, _PRIM, _GEOM, _INST = 12, 15, 16, 17, 18, 19
_RAYHIT8_WORDS = 8 * 21
# RTCRayHit: the same fields, one word each (the ray takes 12 words, 16-byte aligned already)
_RAYHIT1_WORDS = 24
_ARGS_WORDS = 16  # RTCIntersectArguments: flags, feature_mask, then three pointers (zero: the defaults)
_PACKET = 8


@numba.njit(inline="always")
def _aligned(words):
    """A 32-byte-aligned uint32 block of ``words`` words, its float32 view and its address."""
    raw = np.zeros(words + 8, np.uint32)
    skip = ((32 - raw.ctypes.data % 32) % 32) // 4
    block = raw[skip : skip + words]
    return block, block.view(np.float32), block.ctypes.data


@numba.njit(inline="always")
def _finite(origins, directions, s):
    total = 0.0
    for k in range(3):
        total += origins[s, k] * 0.0 + directions[s, k] * 0.0
    return total == 0.0  # NaN or infinity anywhere makes the sum NaN


EDGE = 1e-4  # a packet's hit this close to its triangle's edge (in barycentric weight) is asked again alone


@numba.njit(inline="always")
def _single(embree, origins, directions, s, ints, floats, address, arguments):
    """Ray ``s`` alone (``rtcIntersect1``): its closest triangle, -1 for a miss."""
    for k in range(3):
        floats[_ORG + k] = origins[s, k]
        floats[_DIR + k] = directions[s, k]
    floats[_TNEAR] = 0.0
    floats[_TIME] = 0.0
    floats[_TFAR] = np.inf
    ints[_MASK] = 0xFFFFFFFF
    ints[_ID] = 0
    ints[_FLAGS] = 0
    ints[_GEOM] = _INVALID_ID
    ints[_PRIM] = _INVALID_ID
    ints[_INST] = _INVALID_ID
    _call(embree.intersect1, embree.scene, address, arguments, 0)
    return np.int32(ints[_PRIM]) if ints[_GEOM] != _INVALID_ID else np.int32(-1)


BLOCKS = {1: (4, 2), 2: (2, 2), 4: (2, 1)}
"""Pixels a packet of eight rays takes, wide and high, at each sample count (:func:`packet_order`): a block's
rays part later in the BVH than a run of eight along a row (on ``default`` at 640x360, a painted iteration's
rays cost Embree 15% less in blocks of 4 x 2)."""


def packet_order(width: int, height: int, spp: int, out: np.ndarray) -> np.ndarray:
    """The rays of a ``width x height`` tile at ``spp`` samples a pixel (ray ``(row * width + col) * spp + k``)
    in the order of :data:`BLOCKS` (row by row at other sample counts), into ``out`` (>= width * height * spp,)
    int64; returns its first ``width * height * spp``. Which rays share a packet changes no ray's answer
    (:func:`intersect_rays`), only what they cost."""
    rays = out[: width * height * spp]
    wide, high = BLOCKS.get(spp, (1, 1))
    _blocks(width, height, spp, wide, high, rays)
    return rays


@numba.njit(nogil=True, cache=True)
def _blocks(width, height, spp, wide, high, out):
    """:func:`packet_order`'s order into ``out``: blocks of ``wide x high`` pixels, each row by row, the blocks
    along the rows of blocks, top to bottom (blocks cut short at the tile's right and bottom edges)."""
    at = 0
    for top in range(0, height, high):
        for left in range(0, width, wide):
            for row in range(top, min(top + high, height)):
                for col in range(left, min(left + wide, width)):
                    first = (row * width + col) * spp
                    for k in range(spp):
                        out[at] = first + k
                        at += 1


@numba.njit(nogil=True, cache=True)
def intersect_rays(embree, origins, directions, rays, face, coherent):
    """Closest triangle of each listed ray, found by Embree: ``face[s]`` for every ``s`` in ``rays``.

    embree : :class:`Embree`;  origins, directions : (n, 3) float32, directions unit length;  rays : (m,)
    int64, the rays to trace (in screen order for coherent packets);  face : (n,) int32, written -1 for a miss.
    A ray with a non-finite component is not sent to Embree: it misses. ``coherent``: rays go in packets of
    eight consecutive entries of ``rays`` (fewer than two valid rays go alone), else one by one (scattered
    rays: a packet whose rays part at the root costs more than its rays alone). A kernel passes it as
    ``np.bool_(...)``, not a literal: each literal value would compile a specialisation of its own.

    The answer of a ray does not depend on the rays beside it: where two triangles tie (a ray through their
    shared edge or corner), which one a packet reports depends on the order its traversal took, so a hit
    within ``EDGE`` of its triangle's edge is asked again alone, and a tile stays a crop of the whole image.
    """
    ints, floats, address = _aligned(_RAYHIT8_WORDS + _PACKET + _ARGS_WORDS)
    rayhit, valid, arguments = address, address + 4 * _RAYHIT8_WORDS, address + 4 * (_RAYHIT8_WORDS + _PACKET)
    ints[_RAYHIT8_WORDS + _PACKET] = _QUERY_COHERENT
    ints[_RAYHIT8_WORDS + _PACKET + 1] = _FEATURES_ALL
    one_ints, one_floats, one = _aligned(_RAYHIT1_WORDS)
    m = len(rays)
    for start in range(0, m, _PACKET):
        lanes = min(_PACKET, m - start)
        count = 0
        for lane in range(_PACKET):
            live = lane < lanes and _finite(origins, directions, rays[start + lane])
            ints[_RAYHIT8_WORDS + lane] = 0xFFFFFFFF if live else 0
            count += live
            if not live:
                if lane < lanes:
                    face[rays[start + lane]] = -1
                continue
            s = rays[start + lane]
            for k in range(3):
                floats[(_ORG + k) * 8 + lane] = origins[s, k]
                floats[(_DIR + k) * 8 + lane] = directions[s, k]
            floats[_TNEAR * 8 + lane] = 0.0
            floats[_TIME * 8 + lane] = 0.0
            floats[_TFAR * 8 + lane] = np.inf
            ints[_MASK * 8 + lane] = 0xFFFFFFFF
            ints[_ID * 8 + lane] = 0
            ints[_FLAGS * 8 + lane] = 0
            ints[_GEOM * 8 + lane] = _INVALID_ID
            ints[_PRIM * 8 + lane] = _INVALID_ID
            ints[_INST * 8 + lane] = _INVALID_ID
        if count == 0:
            continue
        if count == 1 or not coherent:  # a lone ray costs less alone
            for lane in range(lanes):
                if ints[_RAYHIT8_WORDS + lane] != 0:
                    s = rays[start + lane]
                    face[s] = _single(embree, origins, directions, s, one_ints, one_floats, one, arguments)
            continue
        _call(embree.intersect8, valid, embree.scene, rayhit, arguments)
        for lane in range(lanes):
            if ints[_RAYHIT8_WORDS + lane] == 0:
                continue
            s = rays[start + lane]
            if ints[_GEOM * 8 + lane] == _INVALID_ID:
                face[s] = -1
                continue
            u = floats[_U * 8 + lane]
            v = floats[_V * 8 + lane]
            if u < EDGE or v < EDGE or u + v > 1.0 - EDGE:
                face[s] = _single(embree, origins, directions, s, one_ints, one_floats, one, arguments)
            else:
                face[s] = np.int32(ints[_PRIM * 8 + lane])


# ---- the scene -----------------------------------------------------------------------------------------


class Tracer:
    """An Embree BVH over one triangle soup (F, 3, 3) float32; safe to query from several threads."""

    def __init__(self, triangles: np.ndarray):
        lib, device = _library(), _device()
        triangles = np.ascontiguousarray(triangles, dtype=RAY_DTYPE)
        soup = triangles.reshape(-1, 3)
        faces = len(soup) // 3
        scene = lib.rtcNewScene(device)
        lib.rtcSetSceneFlags(scene, _SCENE_FLAG_ROBUST)
        geometry = lib.rtcNewGeometry(device, _GEOMETRY_TRIANGLE)
        # Embree's own buffers (it reads vertices 16 bytes at a time: a fourth float pads each one)
        vertices = lib.rtcSetNewGeometryBuffer(geometry, _BUFFER_VERTEX, 0, _FORMAT_FLOAT3, 16, len(soup))
        indices = lib.rtcSetNewGeometryBuffer(geometry, _BUFFER_INDEX, 0, _FORMAT_UINT3, 12, faces)
        _check(device, "to allocate a scene's buffers")
        if faces:
            np.ctypeslib.as_array(ctypes.cast(vertices, ctypes.POINTER(ctypes.c_float)), (len(soup), 4))[:, :3] = soup
            np.ctypeslib.as_array(ctypes.cast(indices, ctypes.POINTER(ctypes.c_uint32)), (faces * 3,))[:] = np.arange(
                faces * 3, dtype=np.uint32
            )
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometry(scene, geometry)
        lib.rtcReleaseGeometry(geometry)
        lib.rtcCommitScene(scene)  # now, once, rather than inside the first (possibly concurrent) query
        _check(device, "to build a scene's BVH")
        self._scene = scene
        self.triangles = triangles  # (F, 3, 3) float32, the scene's own array (where hits are placed)
        self.embree = Embree(scene, _address("rtcIntersect1"), _address("rtcIntersect8"))

    def __del__(self):
        scene = getattr(self, "_scene", None)
        if scene:
            _library().rtcReleaseScene(scene)

    def intersect(self, origins: np.ndarray, directions: np.ndarray, rays: np.ndarray | None = None) -> Hits:
        """Closest hit of each ray (or of the listed ``rays``, (m,) int64, into hits of all n). origins,
        directions : (n, 3) float32, directions unit length. Rays with a non-finite component miss. The face
        is Embree's; where the ray meets it is ``kernels.place_hits``'s (one definition, whoever finds the face)."""
        n = len(origins)
        hits = Hits.misses(n)
        listed = np.arange(n) if rays is None else rays
        intersect_rays(self.embree, origins, directions, listed, hits.face, True)
        place_hits(origins=origins, directions=directions, rays=listed, triangles=self.triangles, hits=hits)
        return hits

    def bare_query(self, origins: np.ndarray, directions: np.ndarray, face: np.ndarray, width: int) -> None:
        """Embree's packet query of every ray into ``face`` (n,) int32 and nothing else, the rays (one a pixel,
        rows of ``width``) in packets as a painting sends them (:func:`packet_order`): the limit an iteration of
        ``rcp bench speed`` is measured against."""
        order = packet_order(width, len(origins) // width, 1, np.empty(len(origins), np.int64))
        intersect_rays(self.embree, origins, directions, order, face, True)


class EmbreexScene:
    """The same BVH built by ``embreex``, queried one ray at a time: what ``rcp bench speed`` compares with."""

    def __init__(self, triangles: np.ndarray):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, np.ascontiguousarray(triangles, dtype=RAY_DTYPE))
        self._scene.run(np.zeros((1, 3), RAY_DTYPE), np.ones((1, 3), RAY_DTYPE), query="DISTANCE")

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> Hits:
        """embreex's answer, for every ray (finite ones only: it passes them all to Embree)."""
        out = self._scene.run(origins, directions, output=1)
        return Hits(out["primID"], out["tfar"], out["u"], out["v"])

    def bare_query(self, origins: np.ndarray, directions: np.ndarray) -> None:
        """embreex's closest-hit query and nothing else."""
        self._scene.run(origins, directions, output=1)
