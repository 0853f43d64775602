"""The traced method: every iteration casts one ray per sample from its per-pixel camera into the scene.

A tile's iteration has three stages: camera assignment (:func:`assign_cameras`: the mapping turns
``I_{n-1}`` into displacements ``V_p, V_e``, and those into rays, fused in ``kernels.cast_rays``),
intersection (Embree, through ``tracer.py``) and shading (``kernels.shade``). :func:`displacements` is
the plain numpy form of the camera assignment's displacements.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import kernels
from .alphamask import pass_masked
from .camera import RAY_DTYPE, Camera, Region, plane_points
from .mappings import MappingInput, get_mapping
from .paintstate import PaintState, TileIteration
from .params import PaintParams
from .sampling import noise_vectors, stratified_offsets
from .scene import Scene
from .stopwatch import Stopwatch
from .tracer import Hits


@dataclass
class TileSetup:
    """What stays fixed over the iterations of one tile: sample offsets, the noise, the camera's numbers."""

    camera: Camera
    region: Region
    xi: np.ndarray  # (n, spp) float64 sub-pixel offsets
    eta: np.ndarray
    noise: np.ndarray | None  # (n, 3) float32 world-space random vectors, when painting with noise
    basis: np.ndarray = field(init=False)  # (3, 3) rows r, u, f
    image_plane: kernels.ImagePlane = field(init=False)  # the image plane and the tile, as the kernels take them
    pixels: np.ndarray = field(init=False)  # (n,) int64 every pixel of the tile: what an iteration paints

    def __post_init__(self):
        self.image_plane = kernels.ImagePlane.of(self.camera, self.region)
        self.basis = self.image_plane.basis
        self.pixels = np.arange(self.region.pixel_count)

    def plane(self) -> np.ndarray:
        """Image-plane points of every sample, (n*spp, 3) float64: the numpy form of what cast_rays builds."""
        i, j = self.region.pixel_coords()
        s = ((i[:, None] + self.xi) / self.region.full_width).ravel()
        t = ((j[:, None] + self.eta) / self.region.full_height).ravel()
        return plane_points(self.camera, self.region, s, t)


def setup_tile(camera: Camera, region: Region, params: PaintParams) -> TileSetup:
    """The constants of ``region``'s iterations seen by ``camera``: exactly those of the same pixels of the
    full image (counter-based sampling), so a tile is a crop."""
    if params.spp == 1 and params.noise == 0:  # the common case needs no pixel coordinates at all
        half = np.full((region.pixel_count, 1), 0.5)
        return TileSetup(camera, region, half, half, None)
    i, j = region.pixel_coords()
    xi, eta = stratified_offsets(params.seed, i, j, params.spp)
    noise = (noise_vectors(params.seed, i, j) @ np.stack(camera.basis())).astype(np.float32) if params.noise else None
    return TileSetup(camera, region, xi, eta, noise)


def _mapping_input(state: PaintState, setup: TileSetup, z0: float) -> MappingInput:
    r, u, f = setup.basis
    i, j = setup.region.pixel_coords()
    return MappingInput(state.color, state.depth, state.normal, state.direction, r, u, f, z0, i, j)


def displacements(state: PaintState, setup: TileSetup, params: PaintParams, z0: float) -> tuple[np.ndarray, np.ndarray]:
    """``(V_p, V_e)`` per pixel from ``I_{n-1}`` in plain numpy: two (n, 3) float64, scene units.

    The reference for what ``kernels.cast_rays`` computes fused; a non-finite displacement moves nothing.
    """
    data = _mapping_input(state, setup, z0)
    noise = 0.0 if setup.noise is None else params.noise * setup.noise

    def scaled(mapping: str, scale: float) -> np.ndarray:
        if scale == 0.0:
            return np.zeros((state.region.pixel_count, 3))
        d = scale * (np.asarray(get_mapping(mapping).field(data), dtype=np.float64) + noise)
        return np.where(np.isfinite(d), d, 0.0)

    pitch = setup.camera.pixel_pitch(setup.region.full_height)
    return scaled(params.mapping, params.lambda_p * pitch), scaled(params.eye_mapping, params.lambda_e)


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


def field_plan(
    state: PaintState, setup: TileSetup, z0: float, mapping: str, scale: float, moves: bool
) -> kernels.Field:
    """How ``kernels.fill_field`` computes the displacement field of ``mapping`` times ``scale`` for
    ``state``: fused for a built-in mapping, given (computed here, in numpy) for a registered one;
    FIELD_ZERO when nothing ``moves`` or the scale is 0."""
    fused = get_mapping(mapping).fused
    if not moves or scale == 0.0:
        return kernels.Field(kernels.FIELD_ZERO, 0.0, kernels.or_dummy(None, 2))
    if fused != kernels.FIELD_GIVEN:
        return kernels.Field(fused, scale, kernels.or_dummy(None, 2))
    given = get_mapping(mapping).field(_mapping_input(state, setup, z0))
    return kernels.Field(kernels.FIELD_GIVEN, scale, np.ascontiguousarray(given, dtype=np.float32))


def assign_cameras(
    state: PaintState, setup: TileSetup, params: PaintParams, z0: float, rays: Rays, pixels: np.ndarray | None = None
) -> int:
    """Camera assignment: fill ``rays`` from ``I_{n-1}`` for ``pixels`` (ascending; default every pixel of
    the tile), sample k of the m-th pixel listed in row m * spp + k. Returns how many rays came out
    non-finite (they must not reach Embree)."""
    pitch = setup.camera.pixel_pitch(setup.region.full_height)
    moves = not state.blank and state.has(params.reads())
    target = field_plan(state, setup, z0, params.mapping, params.lambda_p * pitch, moves)
    eye = field_plan(state, setup, z0, params.eye_mapping, params.lambda_e, moves)
    eye_fixed = eye.kind == kernels.FIELD_ZERO
    bad = kernels.cast_rays(
        eye=np.asarray(setup.camera.eye, np.float64),
        plane=setup.image_plane,
        xi=setup.xi,
        eta=setup.eta,
        previous=kernels.channels(state),
        z0=float(z0),
        target=target,
        eye_field=eye,
        noise=kernels.or_dummy(setup.noise, 2),
        noise_scale=float(params.noise) if moves else 0.0,
        pixels=setup.pixels if pixels is None else pixels,
        v_p=rays.v_p,
        v_e=rays.v_e,
        origins=rays.origins,
        directions=rays.directions,
        write_origins=not (eye_fixed and rays.at_eye),
    )
    rays.at_eye = eye_fixed
    return bad


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
    hits = tracer.intersect(rays.origins, rays.directions)
    kernels.place_hits(
        origins=rays.origins, directions=rays.directions, rays=setup.pixels, triangles=geometry.triangles, hits=hits
    )
    if geometry.masked:  # ---- alpha: cut-outs let rays through (alphamask.py) ----
        pass_masked(tracer, geometry, rays.origins, rays.directions, setup.pixels, hits)
    out.face[:] = hits.face
    out.distance[:] = hits.t


def tile_iteration(
    scene: Scene,
    time: float,
    setup: TileSetup,
    params: PaintParams,
    seen: kernels.Seen | None = None,
    record_seen: kernels.Seen | None = None,
) -> TileIteration:
    """One traced iteration of the tile ``setup`` describes, of ``scene`` at ``time``: ``I_{n-1} -> I_n``.
    It records the channels ``params`` reads; its buffers are the tile's, reused by every iteration.

    With ``params.fast`` an iteration paints again only the pixels whose inputs changed since the
    iteration before (``kernels.changed_pixels``: colors in display levels while the eyes rest, else
    exact), and, given ``seen`` (:func:`visible_faces` of the
    full image, for paintings whose eyes rest), intersects without the BVH where ``seen`` decides
    (``kernels.resolve_seen``). ``record_seen`` (a bundles.Seen of the tile): where to write what this
    iteration's rays hit, for a one-sample iteration from the canvas (whose rays are those of
    :func:`visible_faces`).
    """
    geometry, tracer = scene.geometry(time)
    surfaces = kernels.Surfaces(**{name: getattr(geometry, name) for name in kernels.Surfaces._fields})
    light = scene.light
    light_dir = np.asarray(light.direction if light else (0.0, -1.0, 0.0), np.float64)
    ambient = float(light.ambient if light else 1.0)
    eye = np.asarray(setup.camera.eye, np.float64)
    z0 = params.focus(setup.camera)
    z_max = params.z_max if params.z_max is not None else scene.depth_of_miss(eye, time)
    reads = params.reads()
    triangles = geometry.triangles
    n = setup.region.pixel_count
    rays = Rays.allocate(n, params.spp)
    every_ray = np.arange(n * params.spp)  # the rays an iteration casts are the first of these, in order
    if tracer is None:
        seen = None
    if seen is not None:  # the hits of the rays decided without Embree, and the rays left to it
        decided = Hits(*(np.empty(n * params.spp, a.dtype) for a in Hits.misses(1)))
        pending = np.empty(n * params.spp, np.int64)
    changed = np.empty(n, np.int64) if params.fast else None
    compared = {name: name in reads for name in ("color", "depth", "normal", "direction")}
    # colors compare in display levels while the eyes rest; with moving eyes every shortcut is exact
    color_levels = kernels.DISPLAY_LEVELS if params.lambda_e == 0.0 else 0
    last: list[PaintState] = []  # the state the iteration before started from

    def to_paint(state: PaintState) -> np.ndarray:
        """The pixels this iteration must paint: all of them, or with ``fast`` the ones whose inputs changed."""
        before = last[0] if last else None
        last[:] = [state]
        if changed is None or before is None or before.blank or state.blank or not before.has(reads):
            return setup.pixels
        count = kernels.changed_pixels(
            before=kernels.channels(before),
            after=kernels.channels(state),
            **compared,
            color_levels=color_levels,
            out=changed,
        )
        return changed[:count]

    def intersect(count: int, checked: bool, canvas: bool) -> Hits:
        if tracer is None:
            return Hits.misses(count)
        # an iteration from the canvas is the plain render: traced exactly, always (at one sample it casts
        # the very rays whose hits ``seen`` holds), so ``fast`` never changes the plain render and a first
        # iteration never depends on where ``seen`` came from (a tile stays a crop)
        if seen is None or canvas:
            hits = tracer.intersect(rays.origins[:count], rays.directions[:count], checked=checked)
            kernels.place_hits(
                origins=rays.origins, directions=rays.directions, rays=every_ray[:count], triangles=triangles, hits=hits
            )
            if geometry.masked:  # ---- alpha: cut-outs let rays through (alphamask.py) ----
                pass_masked(tracer, geometry, rays.origins, rays.directions, every_ray[:count], hits)
            return hits
        left = kernels.resolve_seen(
            origins=rays.origins,
            directions=rays.directions,
            count=count,
            plane=setup.image_plane,
            seen=seen,
            triangles=triangles,
            hits=decided,
            pending=pending,
        )
        if left:
            rest = pending[:left]
            found = tracer.intersect(rays.origins[rest], rays.directions[rest])
            decided.face[rest] = found.face
            kernels.place_hits(
                origins=rays.origins, directions=rays.directions, rays=rest, triangles=triangles, hits=decided
            )
        if geometry.masked:  # ---- alpha: cut-outs let rays through, decided and pending alike (alphamask.py) ----
            pass_masked(tracer, geometry, rays.origins, rays.directions, every_ray[:count], decided)
        return decided

    def iterate(state: PaintState, watch: Stopwatch) -> PaintState:
        with watch.stage("camera"):
            pixels = to_paint(state)
            invalid = assign_cameras(state, setup, params, z0, rays, pixels)
        count = len(pixels) * params.spp
        with watch.stage("intersect"):
            hits = intersect(count, invalid == 0, state.blank)
            if record_seen is not None:
                record_seen.face[:] = hits.face[:count]
                record_seen.distance[:] = hits.t[:count]
        with watch.stage("shade"):
            # the pixels not painted keep their value: start from a copy of the state
            new = PaintState.empty(setup.region, reads) if len(pixels) == n else state.copy()
            kernels.shade(
                origins=rays.origins,
                directions=rays.directions,
                hits=hits,
                spp=params.spp,
                pixels=pixels,
                surfaces=surfaces,
                environment=scene.environment.image,
                light_dir=light_dir,
                ambient=ambient,
                lit=light is not None,
                eye=eye,
                forward=setup.basis[2],
                z_max=float(z_max),
                out=kernels.channels(new),
                need_depth=new.depth is not None,
                need_normal=new.normal is not None,
                need_direction=new.direction is not None,
            )
        return new

    return iterate
