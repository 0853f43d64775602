"""The named bundles the kernels take (numba passes tuples of arrays and numbers without copying).

A kernel is called by keyword, with these bundles for the arrays that travel together, so that two
arguments of the same type cannot swap without an error: positionally, a swap gave a wrong image.
"""

from __future__ import annotations

from collections import namedtuple
from typing import NamedTuple

import numpy as np

from ...camera.camera import PROJECTIONS, STEREO, Camera, Region
from ..paintstate import CHANNELS, channel_shape
from .embree import Hits

_DUMMY = {1: np.zeros(1, np.float32), 2: np.zeros((1, 3), np.float32)}

Channels = namedtuple("Channels", CHANNELS, defaults=[_DUMMY[len(channel_shape(name, 1))] for name in CHANNELS[1:]])
Channels.__doc__ = """Per-pixel data of n pixels, row-major, as PaintState holds it (fields: ``paintstate.CHANNELS``).

color : (n, 3) float32;  depth, object, material : (n,) float32;  uv : (n, 2) float32;  the others
(n, 3) float32 (``paintstate.PaintState`` says what each holds). A channel that is not recorded is a
dummy (:func:`channels`; the default of every channel but color): numba needs an array of the right type
even where it reads or writes nothing."""


Records = namedtuple("Records", CHANNELS[1:])  # type: ignore[misc]  # fields from the one list of channels
Records.__doc__ = """Which channels beside color an iteration records (and compares and carries): a bool each, by
the names of ``paintstate.CHANNELS``."""


def records(channels) -> Records:
    """The :data:`Records` of the channel names in ``channels``."""
    return Records(*(name in channels for name in CHANNELS[1:]))


class ImagePlane(NamedTuple):
    """The frame camera's projection and where a tile of the painting lies (``camera.py`` has the formulas,
    ``projection.py`` the kernels' functions over this)."""

    basis: np.ndarray  # (3, 3) float64, rows r, u, f
    tan_half: float  # tan(fov / 2)
    aspect: float  # W / H of an eye's image
    full_width: int  # the painting's size (both eyes of a stereo painting)
    full_height: int
    x0: int  # the tile's top-left pixel
    y0: int
    width: int  # the tile's width: its pixels are row-major
    projection: int  # projection.PERSPECTIVE, EQUIRECT
    layout: int  # projection.MONO, TOP_BOTTOM, SIDE_BY_SIDE
    eye_width: int  # W x H: an eye's image
    eye_height: int
    half_ipd: float  # a pixel's eye sits at eye + side * half_ipd * r_ij
    columns: np.ndarray  # (W, 2) float64 cos, sin of the longitude of each column's centre (equirect; else a dummy)
    rows: np.ndarray  # (H, 2) float64 cos, sin of the latitude of each row's centre

    @classmethod
    def of(cls, camera: Camera, region: Region) -> ImagePlane:
        """The projection of ``camera`` and where ``region`` lies in its painting."""
        width, height = camera.eye_size(region.full_width, region.full_height)
        equirect = camera.projection == "equirect"
        columns = rows = np.zeros((1, 2))
        if equirect:
            phi = (2.0 * (np.arange(width) + 0.5) / width - 1.0) * np.pi
            theta = (1.0 - 2.0 * (np.arange(height) + 0.5) / height) * np.pi / 2.0
            columns = np.stack([np.cos(phi), np.sin(phi)], axis=1)
            rows = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        return cls(
            basis=np.stack(camera.basis()),
            tan_half=camera.half_height(),
            aspect=width / height,
            full_width=region.full_width,
            full_height=region.full_height,
            x0=region.x0,
            y0=region.y0,
            width=region.width,
            projection=PROJECTIONS.index(camera.projection),
            layout=STEREO.index(camera.stereo),
            eye_width=width,
            eye_height=height,
            half_ipd=0.5 * camera.ipd if camera.stereo != "mono" else 0.0,
            columns=columns,
            rows=rows,
        )


class Field(NamedTuple):
    """How :func:`~rcp_server.engine.kernels.cast.fill_field` computes a displacement field (see mappings.py)."""

    kind: int  # FIELD_*
    scale: float  # lambda_p * p for V_p, lambda_e for V_e
    given: np.ndarray  # (n, 3) float32: the field itself when kind is FIELD_GIVEN, else a dummy


class Surfaces(NamedTuple):
    """What shading reads of the scene's triangles (``scene.Geometry`` has the shapes)."""

    triangles: np.ndarray  # (F, 3, 3) float32 world corners (the geometric normal)
    normals: np.ndarray  # (F, 3, 3) float32 unit shading normals per corner
    colors: np.ndarray  # (F, 3, 3) float32 albedo per corner
    uv: np.ndarray  # (F, 3, 2) float32
    texture_id: np.ndarray  # (F,) int32, -1 none
    texels: np.ndarray  # (T, 3) uint8 RGB display colors, every texture packed
    texture_offset: np.ndarray  # (K,) int64 first texel of each texture
    texture_width: np.ndarray  # (K,) int64
    texture_height: np.ndarray  # (K,) int64
    alpha_texels: np.ndarray  # (A,) uint8 coverage of the textures that have one (``alpha.py`` reads it)
    texture_alpha_offset: np.ndarray  # (K,) int64 where a texture's coverage starts in alpha_texels, -1 none
    face_object: np.ndarray  # (F,) int32 the scene's object (``Geometry.object_names``)
    face_material: np.ndarray  # (F,) int32 row of the material tables; row 0 is plain
    material_alpha_cutoff: np.ndarray  # (M,) float32, 0 opaque (``alpha.py`` reads it)


class Cast(NamedTuple):
    """A tile's cameras, as ``cast.cast_rays`` takes them (its docstring has the shapes)."""

    eye: np.ndarray  # (3,) float64
    plane: ImagePlane
    xi: np.ndarray  # (n, spp) float64
    eta: np.ndarray
    z0: float
    target: Field
    eye_field: Field
    noise: np.ndarray  # (n, 3) float32, or a dummy
    noise_scale: float
    write_origins: bool


class Screen(NamedTuple):
    """The screen cells of eyes at rest (``screencells.py`` builds them, ``visibility.py`` reads them): per eye,
    a grid of ``columns x rows`` cells over its image and guard band, each listing the triangles that can cover
    it. ``on`` False: no cells (:data:`NO_SCREEN`), every ray goes to Embree."""

    on: bool
    eyes: np.ndarray  # (E, 3) float32 the rays' origins, exactly, eye by eye
    basis: np.ndarray  # (3, 3) float64 rows r, u, f
    scale_x: float  # a direction d lies in cell column floor(d.r / d.f * scale_x + shift_x)
    shift_x: float
    scale_y: float  # and row floor(d.u / d.f * scale_y + shift_y)
    shift_y: float
    columns: int
    rows: int
    start: np.ndarray  # (E, columns * rows + 1) int32 where each cell's list starts in faces
    cover: np.ndarray  # (E, columns * rows) int32: the face (a record) that answers every ray of the cell when one
    # provably does, -1 when its rays test its list, visibility.LONG_CELL when the list is too long to pay
    faces: np.ndarray  # (K,) int32 the lists, one after the other
    errors: np.ndarray  # (K,) float32 the bound of Embree's error on the listed face's edge functions in the cell
    nearest: np.ndarray  # (K,) float32 the nearest depth Embree can place it at in the cell (lists run front to back)
    records: np.ndarray  # (L, visibility.RECORD) float64 the edge functions and distance of each face listed,
    # for the eye whose lists name it (a face listed for two eyes has two)
    ids: np.ndarray  # (L,) int32 which face of the scene each record is
    seconds: float  # what building them took, thread time

    def nbytes(self) -> int:
        """The bytes of the cells (starts, flags and lists; not the per-face records)."""
        return self.start.nbytes + self.cover.nbytes + self.faces.nbytes + self.errors.nbytes + self.nearest.nbytes


NO_SCREEN = Screen(
    False,
    np.zeros((0, 3), np.float32),
    np.eye(3),
    1.0,
    0.0,
    1.0,
    0.0,
    1,
    1,
    np.zeros((0, 2), np.int32),
    np.zeros((0, 1), np.int32),
    np.zeros(1, np.int32),
    np.zeros(1, np.float32),
    np.zeros(1, np.float32),
    np.zeros((1, 12)),
    np.zeros(1, np.int32),
    0.0,
)


class Trace(NamedTuple):
    """The scene as intersection needs it: Embree's handle (``tracer.Embree``; scene 0 when there are no
    triangles), the triangles (F, 3, 3) float32 where hits are placed, and whether some of them have cut-outs
    that rays pass through (``alpha.pass_masked``, stepping at least ``floor`` scene units past a hit);
    ``screen``: the screen cells that answer the rays of eyes at rest without the BVH, where they can."""

    embree: tuple
    triangles: np.ndarray
    masked: bool
    floor: float
    screen: Screen = NO_SCREEN


class Ink(NamedTuple):
    """Where outlines are drawn (``outlines.py``): per pixel of the painting, row-major, the ink there and the
    distance from its eye to the surface it is on (``projection.to_pixel`` finds a hit's pixel). ``any`` False:
    no material draws outlines (the arrays are dummies)."""

    any: bool
    ink: np.ndarray  # (H*W,) uint8 1 on an edge, else 0 (a byte: the painting keeps it a pixel)
    distance: np.ndarray  # (H*W,) float32 from the pixel's eye to the surface the ink is on


class Materials(NamedTuple):
    """What shading reads of the materials beyond plain, by row of the material tables (row 0 is plain:
    ``scene.Geometry`` has the shapes), and the ink of their outlines."""

    material_emission: np.ndarray  # (M, 3) float32 display color added after the light
    material_emission_texture: np.ndarray  # (M,) int32, -1 none
    material_unlit: np.ndarray  # (M,) bool
    material_bands: np.ndarray  # (M,) int32 toon shading's bands of light, 0: smooth
    material_outline: np.ndarray  # (M,) float32 how dark its outlines (``outlines.py``), 0: none
    ink: Ink  # outlines


class Shading(NamedTuple):
    """What ``shade.shade`` needs of a painting beyond the rays, and the channels it records."""

    surfaces: Surfaces
    environment: np.ndarray  # (h, w, 3) float32
    light_dir: np.ndarray  # (3,) float64
    ambient: float
    lit: bool
    z_max: float
    records: Records  # the channels beside color to record
    # None where every face is plain (most scenes): shade then compiles without the materials' passes, a third
    # of its compile time, which a first start waits for
    materials: Materials | None


class Scratch(NamedTuple):
    """A tile's working buffers, reused by all its iterations (a large allocation inside a kernel costs more
    than the kernel): n pixels, spp samples."""

    v_p: np.ndarray  # (n, 3) float64
    v_e: np.ndarray  # (n, 3) float64
    origins: np.ndarray  # (n*spp, 3) float32
    directions: np.ndarray  # (n*spp, 3) float32
    hits: Hits  # of n*spp rays
    every: np.ndarray  # (n*spp,) int64 0, 1, 2, ...
    packets: np.ndarray  # (n*spp,) int64 the same rays in the order of Embree's packets (embree.packet_order)
    starts: np.ndarray  # (n*spp, 3) float32 where rays through cut-outs go on (one row when none can)
    todo: np.ndarray  # (n*spp,) int64 rays through cut-outs, two lists in turn (one entry when none can)
    next_todo: np.ndarray
    queue: np.ndarray  # (n*spp,) int64 the rays that the screen cells leave to Embree


class Seen(NamedTuple):
    """What the camera sees at the pixel centres of a ``width x height`` image: the hits of its plain render's
    rays, row-major (``seen.visible_faces``): where outlines are drawn, which surface point the other eye
    of a stereo pair sees (``stereo.partners``), what a click picks."""

    face: np.ndarray  # (height * width,) int32, -1: the sky
    distance: np.ndarray  # (height * width,) float32 along the unit ray to the hit, meaningless on the sky
    width: int
    height: int

    @classmethod
    def empty(cls, width: int, height: int) -> Seen:
        n = width * height
        return cls(np.empty(n, np.int32), np.empty(n, np.float32), width, height)


def or_dummy(array: np.ndarray | None, ndim: int) -> np.ndarray:
    """``array``, or a one-row float32 stand-in of ``ndim`` dimensions for a kernel argument that is absent."""
    return array if array is not None else _DUMMY[ndim]


def channels(source) -> Channels:
    """The channels of ``source`` (anything with the attributes of :data:`CHANNELS`, such as a PaintState),
    dummies for those it does not hold."""
    return Channels(*(or_dummy(getattr(source, name), len(channel_shape(name, 1))) for name in CHANNELS))
