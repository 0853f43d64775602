"""The traced method: every iteration casts one ray per sample from its per-pixel camera into the scene.

A tile's iteration has three stages: camera assignment (:func:`assign_cameras`: the mapping turns
``I_{n-1}`` into displacements ``V_p, V_e``, and those into rays, fused in ``kernels.cast_rays``),
intersection (Embree, through ``tracer.py``) and shading (``kernels.shade``). :func:`displacements` is
the plain numpy form of the camera assignment's displacements.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np

from ..camera.camera import RAY_DTYPE, Camera, Region, pixel_frames, sample_targets
from ..engine import kernels
from ..engine.kernels.embree import Embree, Hits, Tracer, intersect_rays
from ..engine.paintstate import PaintState
from ..scene.scene import Scene
from ..settings.mappings import MappingInput, get_mapping
from ..settings.params import PaintParams
from ..util.sampling import noise_vectors, stratified_offsets
from ..util.stopwatch import Stopwatch
from . import fields, outlines, screen
from .alphamask import pass_masked, step_floor
from .fields import Looks


@dataclass
class TileSetup:
    """What stays fixed over the iterations of one tile: sample offsets, the noise, the camera's numbers."""

    camera: Camera
    region: Region
    xi: np.ndarray  # (n, spp) float64 sub-pixel offsets
    eta: np.ndarray
    noise: np.ndarray | None  # (n, 3) float32 world-space random vectors, when painting with noise
    image_plane: kernels.ImagePlane = field(init=False)  # the projection and the tile, as the kernels take them

    def __post_init__(self):
        self.image_plane = kernels.ImagePlane.of(self.camera, self.region)

    @functools.cached_property
    def pixels(self) -> np.ndarray:
        """(n,) int64 every pixel of the tile: what an iteration paints (made when first asked: a traced
        iteration counts its own)."""
        return np.arange(self.region.pixel_count)

    def frames(self) -> tuple[np.ndarray, ...]:
        """Each pixel's eye and local frame ``r_ij, u_ij, f_ij``: four (n, 3) float64 (``camera.pixel_frames``)."""
        return pixel_frames(self.camera, self.region, *self.region.pixel_coords())

    def targets(self) -> np.ndarray:
        """``P_p`` of every sample, (n*spp, 3) float64: the numpy form of what cast_rays builds."""
        return sample_targets(self.camera, self.region, *self.region.pixel_coords(), self.xi, self.eta)

    def pitch(self) -> float:
        """``p``: a pixel's size at unit distance (camera.py), what ``lambda_p`` counts in."""
        return self.camera.pixel_pitch(self.image_plane.eye_height)


@functools.lru_cache(maxsize=4)
def _centres(capacity: int) -> np.ndarray:
    """(capacity, 1) float64 0.5: one sample at each pixel's centre, one array that every tile slices (never
    written: offsets are read)."""
    return np.full((capacity, 1), 0.5)


def setup_tile(camera: Camera, region: Region, params: PaintParams) -> TileSetup:
    """The constants of ``region``'s iterations seen by ``camera``: exactly those of the same pixels of the
    full image (counter-based sampling), so a tile is a crop."""
    noisy = any(look.noise for look in params.looks())
    if params.spp == 1 and not noisy:  # the common case needs no pixel coordinates at all
        half = _centres(1 << max(0, region.pixel_count - 1).bit_length())[: region.pixel_count]
        return TileSetup(camera, region, half, half, None)
    i, j = region.pixel_coords()
    xi, eta = stratified_offsets(params.seed, i, j, params.spp)
    noise = None
    if noisy:  # in each pixel's own frame, so that it means the same all around a panorama
        _, r, u, f = pixel_frames(camera, region, i, j)
        v = noise_vectors(params.seed, i, j)
        noise = (v[:, :1] * r + v[:, 1:2] * u + v[:, 2:] * f).astype(np.float32)
    return TileSetup(camera, region, xi, eta, noise)


def displacements(
    state: PaintState,
    setup: TileSetup,
    params: PaintParams,
    z0: float,
    looks: Looks | None = None,
    anchor: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(V_p, V_e)`` per pixel from ``I_{n-1}`` in plain numpy: two (n, 3) float64, scene units
    (``fields.displacements``; ``looks``: the settings per object and material, default only ``params``;
    ``anchor``: where the surface noise is read).

    The reference for what ``kernels.cast_rays`` computes fused; a non-finite displacement moves nothing.
    """
    i, j = setup.region.pixel_coords()
    data = MappingInput.of(state, setup.frames()[1:], z0, i, j)
    return fields.displacements(state, data, looks or Looks.single(params), setup.pitch(), setup.noise, anchor)


@dataclass(eq=False)  # lent and given back by identity: the same arrays, not equal ones
class TileBuffers:
    """The buffers of one tile's traced iterations, lent to one tile at a time (``workspace.Workspace``): the
    kernels' :class:`kernels.Scratch` and the two states an iteration alternates between, for tiles of up to
    ``capacity`` pixels. A large allocation inside a kernel costs more than the kernel, and a painting needs
    only as many of these as it runs tiles at once, however large it is."""

    scratch: kernels.Scratch
    states: tuple[PaintState, PaintState]
    anchor: np.ndarray | None  # (capacity, 3) float32 the plain render's points, when the states record them
    capacity: int  # pixels
    spp: int

    @classmethod
    def allocate(cls, capacity: int, spp: int, masked: bool, channels: frozenset[str]) -> TileBuffers:
        """Buffers for tiles of up to ``capacity`` pixels at ``spp`` samples; ``masked``: rays may pass
        cut-outs (their lists then have a row per ray); ``channels``: what the states record beside color."""
        rays = capacity * spp
        cut = rays if masked else 1
        scratch = kernels.Scratch(
            v_p=np.empty((capacity, 3)),
            v_e=np.empty((capacity, 3)),
            origins=np.empty((rays, 3), RAY_DTYPE),
            directions=np.empty((rays, 3), RAY_DTYPE),
            hits=Hits.empty(rays),
            every=np.arange(rays),
            starts=np.empty((cut, 3), RAY_DTYPE),
            todo=np.empty(cut, np.int64),
            next_todo=np.empty(cut, np.int64),
            queue=np.empty(rays, np.int64),
        )
        whole = Region(capacity, 1)
        states = (PaintState.empty(whole, channels), PaintState.empty(whole, channels))
        anchor = np.empty((capacity, 3), np.float32) if "position" in channels else None
        return cls(scratch, states, anchor, capacity, spp)

    def fit(self, region: Region) -> tuple[kernels.Scratch, tuple[PaintState, PaintState], np.ndarray | None]:
        """Views of these buffers for ``region``'s pixels (at most ``capacity``): the scratch, the two states
        and the anchor."""
        n = region.pixel_count
        if n > self.capacity:
            raise ValueError(f"a tile of {n} pixels does not fit buffers for {self.capacity}")
        rays = n * self.spp
        s = self.scratch
        cut = slice(None) if len(s.todo) == 1 else slice(rays)
        scratch = kernels.Scratch(
            v_p=s.v_p[:n],
            v_e=s.v_e[:n],
            origins=s.origins[:rays],
            directions=s.directions[:rays],
            hits=Hits(*(a[:rays] for a in s.hits)),
            every=s.every[:rays],
            starts=s.starts[cut],
            todo=s.todo[cut],
            next_todo=s.next_todo[cut],
            queue=s.queue[:rays],
        )
        states = (self.states[0].first(n, region), self.states[1].first(n, region))
        return scratch, states, None if self.anchor is None else self.anchor[:n]


@dataclass
class Rays:
    """One tile's buffers for camera assignment, reused over its iterations (a large allocation inside a
    kernel costs more than the kernel). ``at_eye``: every origin already is the camera's eye."""

    v_p: np.ndarray  # (n, 3) float64 target displacement per pixel
    v_e: np.ndarray  # (n, 3) float64 eye displacement per pixel
    origins: np.ndarray  # (n*spp, 3) float32
    directions: np.ndarray  # (n*spp, 3) float32
    at_eye: bool = False

    @classmethod
    def allocate(cls, pixels: int, spp: int) -> Rays:
        rays = pixels * spp
        return cls(
            np.empty((pixels, 3)), np.empty((pixels, 3)), np.empty((rays, 3), RAY_DTYPE), np.empty((rays, 3), RAY_DTYPE)
        )


def cameras(
    state: PaintState,
    setup: TileSetup,
    params: PaintParams,
    z0: float,
    looks: Looks | None = None,
    write_origins: bool = True,
    anchor: np.ndarray | None = None,
) -> kernels.Cast:
    """The tile's cameras from ``I_{n-1}`` as ``kernels.cast_rays`` takes them (``write_origins``: False when the
    eyes rest and the ray buffers already hold the eye). The common case (``Looks.fused``) leaves the fields
    to the kernel; any other is computed here (:func:`displacements`) and given to it as it is."""
    looks = looks or Looks.single(params)
    pitch = setup.pitch()
    moves = not state.blank and state.has(params.reads())
    still = kernels.Field(kernels.FIELD_ZERO, 0.0, kernels.or_dummy(None, 2))
    target, eye_field, noise_scale = still, still, 0.0
    if moves and looks.fused():
        if params.lambda_p != 0.0:
            target = kernels.Field(get_mapping(params.mapping).fused, params.lambda_p * pitch, target.given)
        if params.lambda_e != 0.0:
            eye_field = kernels.Field(get_mapping(params.eye_mapping).fused, params.lambda_e, target.given)
        noise_scale = float(params.noise)
    elif moves:
        v_p, v_e = displacements(state, setup, params, z0, looks, anchor)
        if looks.targets_move:
            target = kernels.Field(kernels.FIELD_GIVEN, 1.0, v_p.astype(np.float32))
        if looks.eyes_move:
            eye_field = kernels.Field(kernels.FIELD_GIVEN, 1.0, v_e.astype(np.float32))
    return kernels.Cast(
        eye=np.asarray(setup.camera.eye, np.float64),
        plane=setup.image_plane,
        xi=setup.xi,
        eta=setup.eta,
        z0=float(z0),
        target=target,
        eye_field=eye_field,
        noise=kernels.or_dummy(setup.noise, 2),
        noise_scale=noise_scale,
        write_origins=write_origins,
    )


def assign_cameras(
    state: PaintState, setup: TileSetup, params: PaintParams, z0: float, rays: Rays, pixels: np.ndarray | None = None
) -> int:
    """Camera assignment alone: fill ``rays`` from ``I_{n-1}`` for ``pixels`` (ascending; default every pixel of
    the tile), sample k of the m-th pixel listed in row m * spp + k. Returns how many rays came out
    non-finite (they miss). A painting's iteration does this inside ``kernels.paint_iteration``."""
    cast = cameras(state, setup, params, z0)
    return kernels.cast_rays(
        **{name: getattr(cast, name) for name in kernels.Cast._fields},
        previous=kernels.channels(state),
        pixels=setup.pixels if pixels is None else pixels,
        v_p=rays.v_p,
        v_e=rays.v_e,
        origins=rays.origins,
        directions=rays.directions,
    )


def visible_faces(scene: Scene, time: float, camera: Camera, region: Region, out: kernels.Seen) -> None:
    """What ``region``'s pixel centres see, into ``out`` (a bundles.Seen of the region): the hits of the
    plain render's rays at one sample, the very hits of a one-sample painting's first iteration."""
    setup = setup_tile(camera, region, PaintParams(spp=1, noise=0.0))
    rays = Rays.allocate(region.pixel_count, 1)
    assign_cameras(PaintState.canvas(region), setup, PaintParams(), 0.0, rays)
    geometry, tracer = scene.geometry(time)
    if tracer is None:
        out.face[:] = -1
        return
    hits = Hits.misses(region.pixel_count)
    intersect_rays(tracer.embree, rays.origins, rays.directions, setup.pixels, hits.face)
    kernels.place_hits(
        origins=rays.origins, directions=rays.directions, rays=setup.pixels, triangles=geometry.triangles, hits=hits
    )
    if geometry.masked:  # ---- alpha: cut-outs let rays through (alphamask.py) ----
        pass_masked(tracer, geometry, rays.origins, rays.directions, setup.pixels, hits)
    out.face[:] = hits.face
    out.distance[:] = hits.t


def pick(scene: Scene, time: float, camera: Camera, width: int, height: int, x: int, y: int) -> tuple[str, str] | None:
    """What pixel ``(x, y)`` of a ``width x height`` view by ``camera`` shows, at its centre: the names of its
    object and material ("" for a material with no name), or None for the sky (one ray, traced here)."""
    if not (0 <= x < width and 0 <= y < height):
        raise ValueError(f"pixel ({x}, {y}) is not in a {width}x{height} view")
    seen = kernels.Seen.empty(1, 1)
    visible_faces(scene, time, camera, Region(width, height, x, y, 1, 1), seen)
    face = int(seen.face[0])
    if face < 0:
        return None
    geometry, _ = scene.geometry(time)
    return geometry.object_names[geometry.face_object[face]], geometry.material_names[geometry.face_material[face]]


def object_pixels(scene: Scene, time: float, camera: Camera, width: int, height: int, name: str) -> np.ndarray:
    """Which pixel centres of a ``width x height`` view by ``camera`` show the object called ``name`` (what
    :func:`pick` answers): (height, width) bool, row-major, top row first."""
    seen = kernels.Seen.empty(width, height)
    visible_faces(scene, time, camera, Region(width, height), seen)
    geometry, _ = scene.geometry(time)
    if name not in geometry.object_names:
        return np.zeros((height, width), bool)
    hit = seen.face >= 0
    shows = np.zeros(width * height, bool)
    shows[hit] = geometry.face_object[seen.face[hit]] == geometry.object_names.index(name)
    return shows.reshape(height, width)


@dataclass(frozen=True)
class Frame:
    """What every tile of one painting shares: the scene at its time as the kernels take it, looked up once."""

    trace: kernels.Trace
    shading: kernels.Shading
    tracer: Tracer | None  # held while the painting lives: ``trace`` has only its native handle
    looks: Looks  # the settings per object and material, as the scene's indices select them

    @classmethod
    def of(
        cls, scene: Scene, time: float, camera: Camera, params: PaintParams, width: int = 1, height: int = 1
    ) -> Frame:
        """The frame of a ``width x height`` painting (its size: where outlines are drawn)."""
        geometry, tracer = scene.geometry(time)
        light = scene.light
        reads = params.reads()
        z_max = params.z_max if params.z_max is not None else scene.depth_of_miss(np.asarray(camera.eye), time)
        shading = kernels.Shading(
            surfaces=kernels.Surfaces(**{name: getattr(geometry, name) for name in kernels.Surfaces._fields}),
            environment=scene.environment.image,
            light_dir=np.asarray(light.direction if light else (0.0, -1.0, 0.0), np.float64),
            ambient=float(light.ambient if light else 1.0),
            lit=light is not None,
            z_max=float(z_max),
            records=kernels.records(reads),
            ink=ink(scene, time, camera, width, height),
        )
        embree = tracer.embree if tracer is not None else Embree(0, 0, 0)
        cells = screen.cells(camera, params, width, height, geometry.triangles) if tracer else kernels.NO_SCREEN
        trace = kernels.Trace(embree, geometry.triangles, geometry.masked, step_floor(geometry), cells)
        return cls(trace, shading, tracer, Looks.of(params, geometry.object_names, geometry.material_names))


class TracedTile:
    """The traced iterations of one tile, ``I_{n-1} -> I_n`` (a ``paintstate.TileIteration``): set up once
    for the painting, each iteration one compiled call (``kernels.paint_iteration``) into one of the two
    states of the buffers it is lent (:meth:`bind`), in turn (the other holds ``I_{n-1}``).

    ``keeps_anchor``: the tile runs its iterations in several runs, each lent other buffers (the eyes of a
    stereo painting sharing their smudges), so the points where surface noise is read (the plain render's)
    are kept by the tile itself rather than in the buffers of one run.
    """

    def __init__(self, frame: Frame, setup: TileSetup, params: PaintParams, keeps_anchor: bool = False):
        self.frame, self.setup, self.params = frame, setup, params
        self.z0 = params.focus(setup.camera)
        self.keeps_anchor = keeps_anchor
        self.scratch: kernels.Scratch | None = None  # lent by bind(), for the iterations of one run
        self.buffers: tuple[PaintState, PaintState] | None = None
        self.anchor_store: np.ndarray | None = None
        self.at_eye = False  # every origin in the ray buffers already is the camera's eye
        self.source: PaintState | None = None  # what the next iteration's fields read, when not its own state
        self.clock = np.zeros(3, np.int64)
        self.anchor: np.ndarray | None = None  # where the surface noise is read: the plain render's points

    def bind(self, buffers: TileBuffers) -> None:
        """Work in ``buffers`` (lent for one run of this tile's iterations): their ray origins are not yet the
        eye's."""
        self.scratch, self.buffers, self.anchor_store = buffers.fit(self.setup.region)
        self.at_eye = False

    def __call__(self, state: PaintState, watch: Stopwatch) -> PaintState:
        assert self.scratch is not None and self.buffers is not None, "bind() lends a tile its buffers first"
        source = self.source if self.source is not None else state
        cast = cameras(source, self.setup, self.params, self.z0, self.frame.looks, anchor=self.anchor)
        eyes_rest = cast.eye_field.kind == kernels.FIELD_ZERO
        cast = cast._replace(write_origins=not (eyes_rest and self.at_eye))
        # with two eyes, each ray's origin is its own pixel's eye
        self.at_eye = eyes_rest and self.setup.image_plane.half_ipd == 0.0
        out = self.buffers[1] if state.color is self.buffers[0].color else self.buffers[0]
        self.clock[:] = 0
        clock = time.perf_counter()
        kernels.paint_iteration(
            cast=cast,
            source=kernels.channels(source),
            out=kernels.channels(out),
            trace=self.frame.trace,
            shading=self.frame.shading,
            scratch=self.scratch,
            clock=self.clock,
        )
        watch.share(time.perf_counter() - clock, dict(zip(("camera", "intersect", "shade"), self.clock, strict=True)))
        if state.blank and out.position is not None:
            if self.keeps_anchor or self.anchor_store is None:
                self.anchor = out.position.copy()
            else:
                self.anchor = self.anchor_store
                self.anchor[...] = out.position
        return out


INK_BAND = 1 << 14  # pixels of the ink's pass at a time: its float64 work costs some 300 bytes a pixel


def ink(scene, time: float, camera: Camera, width: int, height: int) -> kernels.Ink:
    """The ink of a painting of ``scene`` at ``time`` seen by ``camera`` at ``width x height``; none (no pass
    at all) unless some material draws outlines."""
    geometry, tracer = scene.geometry(time)
    if tracer is None or not (geometry.material_outline > 0).any():
        return outlines.NO_INK
    grid, far = np.zeros(width * height, np.uint8), np.zeros(width * height, np.float32)
    band = max(1, INK_BAND // width)
    for y0 in range(0, height, band):
        # a band and the first row of the next: an edge between the two inks both sides
        rows = Region(width, height, 0, y0, width, min(band + 1, height - y0))
        seen = kernels.Seen.empty(rows.width, rows.height)
        visible_faces(scene, time, camera, rows, seen)
        ink, distance = outlines.edges(seen.face, seen.distance, camera, geometry, rows)
        at = slice(y0 * width, (y0 + rows.height) * width)
        np.maximum(grid[at], ink, out=grid[at])
        far[at] = distance
    return kernels.Ink(True, grid, far)
