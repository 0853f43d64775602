"""The recursion ``I_n = F(I_{n-1}, S(n))``: previous per-pixel data -> per-pixel cameras -> new data.

Each iteration has four stages, timed separately: camera assignment (mapping plus ray building),
intersection (Embree), shading (plus the per-pixel mean), bookkeeping (handing the new data on).

A pixel reads only its own previous value, so the image splits into tiles that run every iteration
independently: tiles go to threads, and a tile gives exactly the pixels of the same region of a full
render. ``I_0`` is mid-grey and moves no ray, so iteration 1 is the plain ray-traced image.
"""

from __future__ import annotations

import os
import time as _time
from collections.abc import Callable
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from . import imagespace, kernels
from .camera import RAY_DTYPE, Camera, Region, plane_points
from .mappings import MappingInput, get_mapping
from .params import EDGES, PaintParams
from .sampling import noise_vectors, stratified_offsets
from .scene import Scene
from .tracer import Hits

STAGES = ("camera", "intersect", "shade", "bookkeeping")
CHANNEL_NAMES = ("color", "depth", "normal", "direction")


class Abandoned(Exception):
    """A painting stopped between iterations because its ``should_stop`` said so (the camera moved on)."""


@dataclass
class PaintState:
    """Per-pixel data of one iteration for a region, row-major. Channels not recorded are None.

    color : (n, 3) float32 in [0, 1];  depth : (n,) float32;  normal, direction : (n, 3) float32
    """

    region: Region
    color: np.ndarray
    depth: np.ndarray | None = None
    normal: np.ndarray | None = None
    direction: np.ndarray | None = None
    blank: bool = False  # I_0: the mid-grey canvas that moves no ray

    @classmethod
    def canvas(cls, region: Region) -> PaintState:
        return cls(region, np.full((region.pixel_count, 3), 0.5, np.float32), blank=True)

    def image(self) -> np.ndarray:
        """The painting, (h, w, 3) float32 in [0, 1]."""
        return self.color.reshape(self.region.height, self.region.width, 3)

    def rows(self, tile: Region) -> PaintState:
        """The part of this state that covers ``tile`` (full-width rows of this region)."""
        a = (tile.y0 - self.region.y0) * self.region.width
        b = a + tile.pixel_count
        pick = {
            name: None if getattr(self, name) is None else getattr(self, name)[a:b]
            for name in ("color", "depth", "normal", "direction")
        }
        return PaintState(tile, blank=self.blank, **pick)

    def resized(self, width: int, height: int) -> PaintState:
        """This state (of a full image) at another size, nearest pixel: a walk-through that changes its
        resolution keeps painting where it was instead of starting over from the canvas."""
        src = self.region
        if (width, height) == (src.width, src.height):
            return self
        x = np.minimum((np.arange(width) + 0.5) * src.width / width, src.width - 1).astype(np.int64)
        y = np.minimum((np.arange(height) + 0.5) * src.height / height, src.height - 1).astype(np.int64)
        pick = (y[:, None] * src.width + x[None, :]).ravel()
        channels = {
            name: None if getattr(self, name) is None else getattr(self, name)[pick]
            for name in ("color", "depth", "normal", "direction")
        }
        return PaintState(Region(width, height), blank=self.blank, **channels)

    def has(self, channels) -> bool:
        return all(getattr(self, name) is not None for name in channels)


@dataclass
class PaintResult:
    state: PaintState
    stage_seconds: dict[str, float]  # summed over tiles (thread time), all iterations
    iterations: list[np.ndarray] = field(default_factory=list)  # (h, w, 3) per iteration when kept

    @property
    def image(self) -> np.ndarray:
        return self.state.image()


@dataclass
class _Frame:
    """What stays fixed over the iterations of one tile: sample offsets, the noise, the camera's numbers."""

    camera: Camera
    region: Region
    xi: np.ndarray  # (n, spp) float64 sub-pixel offsets
    eta: np.ndarray
    noise: np.ndarray | None  # (n, 3) float32 world-space random vectors, when painting with noise
    basis: np.ndarray = field(init=False)  # (3, 3) rows r, u, f
    plane_args: tuple = field(init=False)  # the image plane and the tile, as the kernels take them
    camera_args: tuple = field(init=False)  # the leading arguments of kernels.cast_rays

    def __post_init__(self):
        self.basis = np.stack(self.camera.basis())
        region = self.region
        self.plane_args = (
            self.basis,
            self.camera.half_height(),
            region.full_width / region.full_height,
            region.full_width,
            region.full_height,
            region.x0,
            region.y0,
            region.width,
        )
        self.camera_args = (np.asarray(self.camera.eye, np.float64), *self.plane_args, self.xi, self.eta)

    def plane(self) -> np.ndarray:
        """Image-plane points of every sample, (n*spp, 3) float64: the numpy form of what cast_rays builds."""
        i, j = self.region.pixel_coords()
        s = ((i[:, None] + self.xi) / self.region.full_width).ravel()
        t = ((j[:, None] + self.eta) / self.region.full_height).ravel()
        return plane_points(self.camera, self.region, s, t)


def _frame(camera: Camera, region: Region, params: PaintParams) -> _Frame:
    if params.spp == 1 and params.noise == 0:  # the common case needs no pixel coordinates at all
        half = np.full((region.pixel_count, 1), 0.5)
        return _Frame(camera, region, half, half, None)
    i, j = region.pixel_coords()
    xi, eta = stratified_offsets(params.seed, i, j, params.spp)
    noise = (noise_vectors(params.seed, i, j) @ np.stack(camera.basis())).astype(np.float32) if params.noise else None
    return _Frame(camera, region, xi, eta, noise)


def _mapping_input(state: PaintState, frame: _Frame, z0: float) -> MappingInput:
    r, u, f = frame.basis
    i, j = frame.region.pixel_coords()
    return MappingInput(state.color, state.depth, state.normal, state.direction, r, u, f, z0, i, j)


def displacements(state: PaintState, frame: _Frame, params: PaintParams, z0: float) -> tuple[np.ndarray, np.ndarray]:
    """``(V_p, V_e)`` per pixel from ``I_{n-1}`` in plain numpy: two (n, 3) float64, scene units.

    The reference for what ``kernels.cast_rays`` computes fused; a non-finite displacement moves nothing.
    """
    data = _mapping_input(state, frame, z0)
    noise = 0.0 if frame.noise is None else params.noise * frame.noise

    def scaled(mapping: str, scale: float) -> np.ndarray:
        if scale == 0.0:
            return np.zeros((state.region.pixel_count, 3))
        d = scale * (np.asarray(get_mapping(mapping).field(data), dtype=np.float64) + noise)
        return np.where(np.isfinite(d), d, 0.0)

    pitch = frame.camera.pixel_pitch(frame.region.full_height)
    return scaled(params.mapping, params.lambda_p * pitch), scaled(params.eye_mapping, params.lambda_e)


@dataclass
class _Rays:
    """One tile's buffers for camera assignment, reused over its iterations (a large allocation inside a
    kernel costs more than the kernel). ``at_eye``: every origin already is the frame's eye."""

    v_p: np.ndarray  # (n, 3) float64 target displacement per pixel
    v_e: np.ndarray  # (n, 3) float64 eye displacement per pixel
    origins: np.ndarray  # (n*spp, 3) float32
    directions: np.ndarray  # (n*spp, 3) float32
    at_eye: bool = False

    @classmethod
    def allocate(cls, pixels: int, spp: int) -> _Rays:
        rays = pixels * spp
        return cls(
            np.empty((pixels, 3)), np.empty((pixels, 3)), np.empty((rays, 3), RAY_DTYPE), np.empty((rays, 3), RAY_DTYPE)
        )


def _plan(
    state: PaintState, frame: _Frame, z0: float, name: str, scale: float, moves: bool
) -> tuple[int, float, np.ndarray]:
    """How ``kernels.fill_field`` computes one displacement field: ``(FIELD_* kind, scale, given field)``."""
    mapping = get_mapping(name)
    if not moves or scale == 0.0:
        return kernels.FIELD_ZERO, 0.0, _DUMMY[2]
    if mapping.fused != kernels.FIELD_GIVEN:
        return mapping.fused, scale, _DUMMY[2]
    given = mapping.field(_mapping_input(state, frame, z0))
    return kernels.FIELD_GIVEN, scale, np.ascontiguousarray(given, dtype=np.float32)


def _cast(state: PaintState, frame: _Frame, params: PaintParams, z0: float, rays: _Rays) -> int:
    """Camera assignment: fill ``rays`` from ``I_{n-1}``. Returns how many rays came out non-finite (they
    must not reach Embree)."""
    pitch = frame.camera.pixel_pitch(frame.region.full_height)
    moves = not state.blank and state.has(params.reads())
    target = _plan(state, frame, z0, params.mapping, params.lambda_p * pitch, moves)
    eye = _plan(state, frame, z0, params.eye_mapping, params.lambda_e, moves)
    eye_fixed = eye[0] == kernels.FIELD_ZERO
    bad = kernels.cast_rays(
        *frame.camera_args,
        state.color,
        _or_dummy(state.depth, 1),
        _or_dummy(state.normal, 2),
        _or_dummy(state.direction, 2),
        float(z0),
        *target,
        *eye,
        _or_dummy(frame.noise, 2),
        float(params.noise) if moves else 0.0,
        rays.v_p,
        rays.v_e,
        rays.origins,
        rays.directions,
        not (eye_fixed and rays.at_eye),
    )
    rays.at_eye = eye_fixed
    return bad


def _paint_tile(
    scene: Scene,
    time: float,
    frame: _Frame,
    params: PaintParams,
    state: PaintState,
    keep: list[np.ndarray] | None,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[PaintState, dict[str, float]]:
    geometry, tracer = scene.geometry(time)
    light = scene.light
    light_dir = np.asarray(light.direction if light else (0.0, -1.0, 0.0), np.float64)
    eye = np.asarray(frame.camera.eye, np.float64)
    forward = frame.basis[2]
    z0 = params.focus(frame.camera)
    z_max = params.z_max if params.z_max is not None else scene.depth_of_miss(eye, time)
    reads = params.reads()
    n_pix = frame.region.pixel_count
    n_rays = n_pix * params.spp
    seconds = dict.fromkeys(STAGES, 0.0)
    rays = _Rays.allocate(n_pix, params.spp)
    origins, directions = rays.origins, rays.directions
    for iteration in range(params.iterations):
        if should_stop is not None and should_stop():
            raise Abandoned
        # ---- camera assignment ----
        clock = _time.perf_counter()
        invalid = _cast(state, frame, params, z0, rays)
        # ---- intersection ----
        now = _time.perf_counter()
        seconds["camera"] += now - clock
        clock = now
        if tracer is None:
            hits = Hits.misses(n_rays)
        else:
            hits = tracer.intersect(origins, directions, checked=invalid == 0)
        # ---- shading ----
        now = _time.perf_counter()
        seconds["intersect"] += now - clock
        clock = now
        new = PaintState(
            frame.region,
            np.empty((n_pix, 3), np.float32),
            depth=np.empty(n_pix, np.float32) if "depth" in reads else None,
            normal=np.empty((n_pix, 3), np.float32) if "normal" in reads else None,
            direction=np.empty((n_pix, 3), np.float32) if "direction" in reads else None,
        )
        kernels.shade(
            origins,
            directions,
            hits.face,
            hits.t,
            hits.b1,
            hits.b2,
            params.spp,
            geometry.normals,
            geometry.colors,
            geometry.uv,
            geometry.texture_id,
            geometry.texels,
            geometry.texture_offset,
            geometry.texture_width,
            geometry.texture_height,
            scene.environment.image,
            light_dir,
            float(light.ambient if light else 1.0),
            light is not None,
            eye,
            forward,
            float(z_max),
            new.color,
            _or_dummy(new.depth, 1),
            _or_dummy(new.normal, 2),
            _or_dummy(new.direction, 2),
            new.depth is not None,
            new.normal is not None,
            new.direction is not None,
        )
        # ---- bookkeeping ----
        now = _time.perf_counter()
        seconds["shade"] += now - clock
        clock = now
        state = new
        if keep is not None:
            a = frame.region.y0 * frame.region.width
            keep[iteration].reshape(-1, 3)[a : a + n_pix] = state.color
        seconds["bookkeeping"] += _time.perf_counter() - clock
    return state, seconds


_DUMMY = {1: np.zeros(1, np.float32), 2: np.zeros((1, 3), np.float32)}


def _or_dummy(array: np.ndarray | None, ndim: int) -> np.ndarray:
    # numba needs an array of the right type even for an output it will not write
    return array if array is not None else _DUMMY[ndim]


TILE_WORK = 1 << 18  # most rays x iterations one tile may hold its thread for (about 50 ms on our machine)


def tile_rows(region: Region, threads: int, rays_per_pixel: int = 1) -> int:
    """Rows per tile: bands of whole rows keep a tile contiguous in memory, and four tiles a thread balance
    the load (smaller tiles, measured with rcp bench speed at 8k and 4k pixels, lost more to per-call
    overhead than they gained in cache). ``rays_per_pixel`` (samples x iterations) caps a tile's work at
    ``TILE_WORK``: a tile keeps its thread through all its iterations, and paintings sharing a pool wait
    for the tiles in progress, so a large painting must not hold the cores in long tiles."""
    balanced = -(-region.height // (threads * 4))
    return max(1, min(balanced, TILE_WORK // (region.width * rays_per_pixel)))


def default_threads() -> int:
    return max(1, min(len(os.sched_getaffinity(0)), 32))


def paint(
    scene: Scene,
    camera: Camera,
    width: int,
    height: int,
    params: PaintParams,
    *,
    time: float = 0.0,
    previous: PaintState | None = None,
    region: Region | None = None,
    threads: int | None = None,
    keep_iterations: bool = False,
    pool: Executor | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> PaintResult:
    """Paint ``region`` (default: all) of a ``width x height`` image of ``scene`` seen by ``camera``.

    Per-frame mode: ``previous=None`` starts from ``I_0`` and runs ``params.iterations`` iterations.
    Temporal mode: pass the previous frame's :attr:`PaintResult.state` to continue the recursion from it
    with this frame's camera and time (it must cover the same region; otherwise the canvas restarts).

    Tiles run on ``pool`` when given (a server shares one pool between all its paintings, so their tiles
    queue for the same cores; pass its size as ``threads``), else on a pool of this call's own. ``should_stop`` is
    asked before every iteration of every tile; once it says yes the painting raises :class:`Abandoned`.
    """
    region = region or Region(width, height)
    if (region.full_width, region.full_height) != (width, height):
        raise ValueError("region belongs to an image of another size")
    if params.method == "image" and region != Region(width, height):
        raise ValueError("the image-space method needs the full image: its lookups reach anywhere on screen")
    if previous is None or previous.region != region:
        previous = PaintState.canvas(region)
    threads = threads or default_threads()
    scene.geometry(time)  # build (or fetch) the BVH once, before the tiles ask for it
    tiles = region.tiles(tile_rows(region, threads, params.spp * params.iterations))
    keep = [np.empty((height, width, 3), np.float32) for _ in range(params.iterations)] if keep_iterations else None
    if keep is not None and region != Region(width, height):
        raise ValueError("keep_iterations needs the full image")

    def on_tiles(run) -> list:
        nonlocal pool
        if pool is not None:
            return list(pool.map(run, tiles))
        if threads == 1 or len(tiles) == 1:
            return [run(tile) for tile in tiles]
        with ThreadPoolExecutor(threads, thread_name_prefix="rcp-tile") as own:
            return list(own.map(run, tiles))

    if params.method == "raytrace":
        parts = on_tiles(
            lambda tile: _paint_tile(
                scene, time, _frame(camera, tile, params), params, previous.rows(tile), keep, should_stop
            )
        )
    else:
        # ---- the plain render, traced: iteration 1 of a new painting, the source of every lookup ----
        temporal = not previous.blank
        once = replace(params, iterations=1)
        plain_keep = keep[:1] if keep is not None and not temporal else None
        canvas = PaintState.canvas(region)
        traced = on_tiles(
            lambda tile: _paint_tile(
                scene, time, _frame(camera, tile, once), once, canvas.rows(tile), plain_keep, should_stop
            )
        )
        plain = _join([p[0] for p in traced], region)
        # ---- the later iterations (all of them in temporal mode), looked up tile by tile ----
        start = previous if temporal else plain
        lookups = params.iterations if temporal else params.iterations - 1
        kept = (keep if temporal else keep[1:]) if keep is not None else None
        looked = on_tiles(
            lambda tile: _look_up_tile(
                _frame(camera, tile, params), params, plain, start.rows(tile), lookups, kept, should_stop
            )
        )
        parts = [(state, {k: traced[n][1][k] + looked[n][1][k] for k in STAGES}) for n, (state, _) in enumerate(looked)]
    state = _join([p[0] for p in parts], region)
    seconds = {stage: sum(p[1][stage] for p in parts) for stage in STAGES}
    return PaintResult(state, seconds, keep or [])


def _look_up_tile(
    frame: _Frame,
    params: PaintParams,
    plain: PaintState,
    state: PaintState,
    iterations: int,
    keep: list[np.ndarray] | None,
    should_stop: Callable[[], bool] | None,
) -> tuple[PaintState, dict[str, float]]:
    """``iterations`` image-space iterations of one tile: each pixel looks up ``plain`` (the full frame's plain
    render, every recorded channel) where its displaced target projects, one bilinear lookup per pixel at
    its centre (samples per pixel only antialias the plain render). Stage times: "camera" is the
    displacement, "shade" the projection and lookup. A state that cannot move a pixel (the canvas, a
    missing channel) leaves it its plain value.
    """
    region = frame.region
    camera = frame.camera
    z0 = params.focus(camera)
    reads = params.reads()
    seconds = dict.fromkeys(STAGES, 0.0)
    pitch = camera.pixel_pitch(region.full_height)
    edge = EDGES.index(params.edge)
    v_p = np.zeros((region.pixel_count, 3))
    for iteration in range(iterations):
        if should_stop is not None and should_stop():
            raise Abandoned
        # ---- camera assignment: V_p, the same fused fields as the traced method ----
        clock = _time.perf_counter()
        moves = not state.blank and state.has(reads)
        kind, scale, given = _plan(state, frame, z0, params.mapping, params.lambda_p * pitch, moves)
        if kind != kernels.FIELD_ZERO:
            kernels.fill_field(
                kind,
                scale,
                frame.basis,
                state.color,
                _or_dummy(state.depth, 1),
                _or_dummy(state.normal, 2),
                _or_dummy(state.direction, 2),
                float(z0),
                given,
                _or_dummy(frame.noise, 2),
                float(params.noise),
                v_p,
            )
        # ---- lookup: every recorded channel, where the displaced ray crosses the image plane ----
        now = _time.perf_counter()
        seconds["camera"] += now - clock
        clock = now
        new = PaintState(
            region,
            np.empty((region.pixel_count, 3), np.float32),
            *(
                None if getattr(plain, name) is None else np.empty_like(getattr(plain, name)[: region.pixel_count])
                for name in CHANNEL_NAMES[1:]
            ),
        )
        imagespace.look_up(
            v_p,
            kind != kernels.FIELD_ZERO,
            *frame.plane_args,
            edge,
            plain.color,
            _or_dummy(plain.depth, 1),
            _or_dummy(plain.normal, 2),
            _or_dummy(plain.direction, 2),
            new.color,
            _or_dummy(new.depth, 1),
            _or_dummy(new.normal, 2),
            _or_dummy(new.direction, 2),
        )
        # ---- bookkeeping ----
        now = _time.perf_counter()
        seconds["shade"] += now - clock
        clock = now
        state = new
        if keep is not None:
            a = region.y0 * region.width
            keep[iteration].reshape(-1, 3)[a : a + region.pixel_count] = state.color
        seconds["bookkeeping"] += _time.perf_counter() - clock
    return state, seconds


def _join(states: list[PaintState], region: Region) -> PaintState:
    def cat(name):
        arrays = [getattr(s, name) for s in states]
        return None if arrays[0] is None else np.concatenate(arrays)

    return PaintState(region, cat("color"), cat("depth"), cat("normal"), cat("direction"))
