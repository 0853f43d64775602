"""The traced method: every iteration casts one ray per sample from its per-pixel camera into the scene.

A tile's iteration has three stages: camera assignment (:func:`assign_cameras`: the mapping turns
``I_{n-1}`` into displacements ``V_p, V_e``, and those into rays, fused in ``kernels.cast_rays``),
intersection (Embree, through ``tracer.py``) and shading (``kernels.shade``). :func:`displacements` is
the plain numpy form of the camera assignment's displacements.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..camera.camera import RAY_DTYPE, Camera, Region, pixel_frames, sample_targets
from ..engine import kernels
from ..engine.paintstate import PaintState
from ..engine.tracer import Embree, Hits, Tracer, intersect_rays
from ..scene.scene import Scene
from ..settings.mappings import MappingInput, get_mapping
from ..settings.params import PaintParams
from ..util.sampling import noise_vectors, stratified_offsets
from ..util.stopwatch import Stopwatch
from . import fields, outlines
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
    pixels: np.ndarray = field(init=False)  # (n,) int64 every pixel of the tile: what an iteration paints

    def __post_init__(self):
        self.image_plane = kernels.ImagePlane.of(self.camera, self.region)
        self.pixels = np.arange(self.region.pixel_count)

    def frames(self) -> tuple[np.ndarray, ...]:
        """Each pixel's eye and local frame ``r_ij, u_ij, f_ij``: four (n, 3) float64 (``camera.pixel_frames``)."""
        return pixel_frames(self.camera, self.region, *self.region.pixel_coords())

    def targets(self) -> np.ndarray:
        """``P_p`` of every sample, (n*spp, 3) float64: the numpy form of what cast_rays builds."""
        return sample_targets(self.camera, self.region, *self.region.pixel_coords(), self.xi, self.eta)

    def pitch(self) -> float:
        """``p``: a pixel's size at unit distance (camera.py), what ``lambda_p`` counts in."""
        return self.camera.pixel_pitch(self.image_plane.eye_height)


def setup_tile(camera: Camera, region: Region, params: PaintParams) -> TileSetup:
    """The constants of ``region``'s iterations seen by ``camera``: exactly those of the same pixels of the
    full image (counter-based sampling), so a tile is a crop."""
    noisy = any(look.noise for look in params.looks())
    if params.spp == 1 and not noisy:  # the common case needs no pixel coordinates at all
        half = np.full((region.pixel_count, 1), 0.5)
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
    plain render's rays at one sample, the very hits of a one-sample painting's first iteration. ``fast``
    paintings read it for the whole image (``kernels.resolve_seen``)."""
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


def thin_parts(scene: Scene, time: float, camera: Camera, rows: Region, out: kernels.Seen) -> None:
    """Where geometry thinner than the grid lies between the pixel centres of ``rows`` (full-width rows of a
    seen grid), into ``out.near`` (a bundles.Seen of those rows): ``kernels.cover_thin``."""
    geometry, tracer = scene.geometry(time)
    out.near[:] = np.inf
    if tracer is None:
        return
    kernels.cover_thin(
        triangles=geometry.triangles,
        eye=np.asarray(camera.eye, np.float64),
        plane=kernels.ImagePlane.of(camera, rows),
        rows=rows.height,
        near=out.near,
    )


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
            ink=outlines.ink(scene, time, camera, width, height),
        )
        embree = tracer.embree if tracer is not None else Embree(0, 0, 0)
        trace = kernels.Trace(embree, geometry.triangles, geometry.masked, step_floor(geometry))
        return cls(trace, shading, tracer, Looks.of(params, geometry.object_names, geometry.material_names))


class TracedTile:
    """The traced iterations of one tile, ``I_{n-1} -> I_n`` (a ``paintstate.TileIteration``): set up once
    for the painting, each iteration one compiled call (``kernels.paint_iteration``) into one of the tile's
    two buffers, in turn (the other holds ``I_{n-1}``).

    With ``params.fast`` an iteration paints again only the pixels whose inputs changed since the
    iteration before (``kernels.changed_pixels``: colors in display levels while the eyes rest, else
    exact), and, given ``seen`` (:func:`visible_faces` of the full image, for paintings whose eyes rest),
    intersects without the BVH where ``seen`` decides (``kernels.resolve_seen``). An iteration from the
    canvas is the plain render, traced exactly, always (at one sample it casts the very rays whose hits
    ``seen`` holds), so ``fast`` never changes the plain render and a first iteration never depends on where
    ``seen`` came from (a tile stays a crop). ``record_seen`` (a bundles.Seen of the tile): where such an
    iteration at one sample writes what its rays hit.
    """

    def __init__(
        self,
        frame: Frame,
        setup: TileSetup,
        params: PaintParams,
        seen: kernels.Seen | None = None,
        record_seen: kernels.Seen | None = None,
    ):
        self.frame, self.setup, self.params = frame, setup, params
        self.seen = seen if frame.tracer is not None else None
        self.record_seen = record_seen
        self.z0 = params.focus(setup.camera)
        self.reads = params.reads()
        n, spp = setup.region.pixel_count, params.spp
        self.scratch = kernels.Scratch(
            v_p=np.empty((n, 3)),
            v_e=np.empty((n, 3)),
            origins=np.empty((n * spp, 3), RAY_DTYPE),
            directions=np.empty((n * spp, 3), RAY_DTYPE),
            hits=Hits.empty(n * spp),
            pending=np.empty(n * spp, np.int64),
            changed=np.empty(n, np.int64),
            every=np.arange(n * spp),
            starts=np.empty((n * spp if frame.trace.masked else 1, 3), RAY_DTYPE),
            todo=np.empty(n * spp if frame.trace.masked else 1, np.int64),
            next_todo=np.empty(n * spp if frame.trace.masked else 1, np.int64),
        )
        self.buffers = (PaintState.empty(setup.region, self.reads), PaintState.empty(setup.region, self.reads))
        self.at_eye = False  # every origin in the ray buffers already is the camera's eye
        self.last: PaintState | None = None  # the state the iteration before started from
        self.source: PaintState | None = None  # what the next iteration's fields read, when not its own state
        self.clock = np.zeros(3, np.int64)
        self.anchor: np.ndarray | None = None  # where the surface noise is read: the plain render's points

    def __call__(self, state: PaintState, watch: Stopwatch) -> PaintState:
        params, reads, before = self.params, self.reads, self.last
        self.last = state
        source = self.source if self.source is not None else state
        compare = params.fast and before is not None and not (before.blank or state.blank) and before.has(reads)
        compare = compare and self.source is None  # a shared source changes with other pixels than this one
        cast = cameras(source, self.setup, params, self.z0, self.frame.looks, anchor=self.anchor)
        eyes_rest = cast.eye_field.kind == kernels.FIELD_ZERO
        cast = cast._replace(write_origins=not (eyes_rest and self.at_eye))
        # with two eyes, ray m is another pixel's, and so another eye's, when the pixels painted change
        self.at_eye = eyes_rest and self.setup.image_plane.half_ipd == 0.0
        out = self.buffers[1] if state.color is self.buffers[0].color else self.buffers[0]
        use_seen = self.seen is not None and not state.blank
        self.clock[:] = 0
        clock = time.perf_counter()
        kernels.paint_iteration(
            cast=cast,
            compare=kernels.Compare(
                any=compare,
                color="color" in reads,
                channels=kernels.records(reads),
                # colors compare in display levels while the eyes rest; with moving eyes every shortcut is exact
                color_levels=kernels.REUSE_LEVELS if not self.frame.looks.eyes_move else 0,
            ),
            before=kernels.channels(before if compare else state),
            previous=kernels.channels(state),
            source=kernels.channels(source),
            out=kernels.channels(out),
            trace=self.frame.trace,
            seen=self.seen if use_seen else _NO_SEEN,
            use_seen=use_seen,
            shading=self.frame.shading,
            scratch=self.scratch,
            clock=self.clock,
        )
        watch.share(time.perf_counter() - clock, dict(zip(("camera", "intersect", "shade"), self.clock, strict=True)))
        if state.blank and out.position is not None:
            self.anchor = out.position.copy()
        if self.record_seen is not None and state.blank and params.spp == 1:
            self.record_seen.face[:] = self.scratch.hits.face
            self.record_seen.distance[:] = self.scratch.hits.t
        return out


_NO_SEEN = kernels.Seen.empty(1, 1)
