"""The recursion ``I_n = F(I_{n-1}, S(n))``: previous per-pixel data -> per-pixel cameras -> new data.

Each iteration has the four stages of ``stopwatch.STAGES``, timed separately. How an iteration sees
its displaced targets is the method's: traced (``raytrace.py``) or looked up in the plain render
(``imagespace.py``); both offer the same tile interface (``paintstate.TileIteration``).

A pixel reads only its own previous value, so the image splits into tiles that run every iteration
independently: tiles go to threads, and a tile gives exactly the pixels of the same region of a full
render. ``I_0`` is mid-grey and moves no ray, so iteration 1 is the plain ray-traced image.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..camera.camera import Camera, Region
from ..engine import kernels
from ..engine.paintstate import Abandoned, PaintState, TileIteration
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util.stopwatch import STAGES, Stopwatch, total
from . import imagespace, raytrace, stereo
from .raytrace import setup_tile

__all__ = [
    "STAGES",
    "Abandoned",
    "PaintResult",
    "PaintState",
    "TILE_WORK",
    "default_threads",
    "paint",
    "see",
    "seen_grid",
    "uses_seen",
    "tile_rows",
]


@dataclass
class PaintResult:
    state: PaintState
    stage_seconds: dict[str, float]  # summed over tiles (thread time), all iterations
    iterations: list[np.ndarray] = field(default_factory=list)  # (h, w, 3) per iteration when kept

    @property
    def image(self) -> np.ndarray:
        return self.state.image()


def _run_tile(
    iterate: TileIteration,
    state: PaintState,
    iterations: int,
    keep: list[np.ndarray] | None,
    should_stop: Callable[[], bool] | None,
) -> tuple[PaintState, dict[str, float]]:
    """``iterations`` iterations of one tile from ``state``: the tile's last state and its stage seconds.
    ``keep`` (full images, one per iteration) gets each iteration's color at the tile's rows."""
    watch = Stopwatch()
    for iteration in range(iterations):
        if should_stop is not None and should_stop():
            raise Abandoned
        state = iterate(state, watch)
        with watch.stage("bookkeeping"):
            if keep is not None:
                state.paste_color(keep[iteration])
    return state, watch.seconds


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
    seen: kernels.Seen | None = None,
) -> PaintResult:
    """Paint ``region`` (default: all) of a ``width x height`` image of ``scene`` seen by ``camera`` (a stereo
    camera's painting holds both eyes' images: ``camera.image_size`` of one eye's).

    Per-frame mode: ``previous=None`` starts from ``I_0`` and runs ``params.iterations`` iterations.
    Temporal mode: pass the previous frame's :attr:`PaintResult.state` to continue the recursion from it
    with this frame's camera and time (it must cover the same region; otherwise the canvas restarts).

    Tiles run on ``pool`` when given (a server shares one pool between all its paintings, so their tiles
    queue for the same cores; pass its size as ``threads``), else on a pool of this call's own. ``should_stop`` is
    asked before every iteration of every tile; once it says yes the painting raises :class:`Abandoned`.

    ``seen``: what the pixel centres of the whole :func:`seen_grid` see (:func:`see`), found already, for a
    region painted apart from the rest of its image (on Ray, a band an actor): else the painting finds it
    itself, over the whole image, whatever its region.
    """
    camera.check_painting(width, height)
    region = region or Region(width, height)
    if (region.full_width, region.full_height) != (width, height):
        raise ValueError("region belongs to an image of another size")
    if params.method == "image" and region != Region(width, height):
        raise ValueError("the image-space method needs the full image: its lookups reach anywhere on screen")
    shared = camera.eyes == "shared" and camera.stereo != "mono"
    if shared and (region != Region(width, height) or params.method != "raytrace"):
        raise ValueError("eyes that share their smudges are traced, over the whole painting (the right reads the left)")
    scene.check_names(params)
    if previous is None or previous.region != region:
        previous = PaintState.canvas(region)
    threads = threads or default_threads()
    frame = raytrace.Frame.of(
        scene, time, camera, params, width, height
    )  # the scene as every tile's kernels take it, once
    tiles = region.tiles(tile_rows(region, threads, params.spp * params.iterations))
    keep = [np.empty((height, width, 3), np.float32) for _ in range(params.iterations)] if keep_iterations else None
    if keep is not None and region != Region(width, height):
        raise ValueError("keep_iterations needs the full image")

    def on_tiles(work, over: list[Region] = tiles) -> list:
        if pool is not None:
            return list(pool.map(work, over))
        if threads == 1 or len(over) == 1:
            return [work(tile) for tile in over]
        with ThreadPoolExecutor(threads, thread_name_prefix="rcp-tile") as own:
            return list(own.map(work, over))

    def run(
        iteration: Callable[[Region], TileIteration], start, iterations: int, keep, beside: Callable | None = None
    ) -> list:
        """Every tile: ``iterations`` of ``iteration(tile)`` from ``start`` (a PaintState of the region, or one
        per tile); each tile's state and seconds. ``beside``: a job for the same pool at the same time."""

        def one(n: int) -> tuple[PaintState, dict[str, float]]:
            if n == len(tiles):
                beside()
                return None
            tile = tiles[n]
            begin = start[n] if isinstance(start, list) else start.rows(tile)
            return _run_tile(iteration(tile), begin, iterations, keep, should_stop)

        # the job beside first: started with the tiles, on a core of its own, it ends with them (queued last, it
        # ran alone once they were done, the other cores idle)
        order = ([len(tiles)] if beside is not None else []) + list(range(len(tiles)))
        return on_tiles(one, order)[1:] if beside is not None else on_tiles(one, order)

    def then(first: list, rest: list) -> list:
        """The parts of two runs over the same tiles, one after the other: the second's states, both's seconds."""
        return [(state, total([first[n][1], seconds])) for n, (state, seconds) in enumerate(rest)]

    full = Region(width, height)
    grid = seen_grid(scene, time, camera, width, height, params)
    given = seen is not None
    if given and (grid is None or (seen.width, seen.height) != (grid.width, grid.height)):
        raise ValueError("seen does not cover this painting's grid of pixel centres (seen_grid)")
    if not given and grid is not None:
        seen = kernels.Seen.empty(grid.width, grid.height)
    # a one-sample painting's first iteration casts the plain render's rays: what they hit comes free
    free = previous.blank and params.spp == 1 and region == full and not given
    extra: list[dict[str, float]] = []  # seconds outside the tiles' iterations

    painters: dict[Region, raytrace.TracedTile] = {}

    def traced(tile: Region) -> TileIteration:
        """The traced iterations of a tile, set up once for the painting (both runs of the fast path use it).
        A painting whose first iteration is free records what it hits into ``seen``."""
        if tile not in painters:
            record = seen.rows(tile) if seen is not None and free else None
            painters[tile] = raytrace.TracedTile(frame, setup_tile(camera, tile, params), params, seen, record)
        return painters[tile]

    sources: list[np.ndarray] = []  # with shared eyes: the pixel each pixel's fields read (stereo.shared_sources)

    def iterate(start, iterations: int, keep) -> list:
        """``iterations`` traced iterations of every tile from ``start`` (as :func:`run`); with shared eyes one
        iteration at a time over the whole painting, each reading what the eyes share of the one before."""
        if not shared:
            return run(traced, start, iterations, keep)
        parts: list = []
        for n in range(iterations):
            states = start if not parts else [p[0] for p in parts]
            whole = PaintState.joined(states, region) if isinstance(states, list) else states
            source = None
            if not whole.blank:
                if not sources:
                    known = seen if seen is not None and (seen.width, seen.height) == (width, height) else None
                    sources.append(stereo.shared_sources(scene, time, camera, region, known))
                source = whole.gathered(sources[0])
            for tile in tiles:
                traced(tile).source = source.rows(tile) if source is not None else None
            step = run(traced, states, 1, keep[n : n + 1] if keep is not None else None)
            parts = then(parts, step) if parts else step
        return parts

    if seen is not None and free:
        # ---- fast, eyes at rest: the first iteration casts the plain render's rays; what they hit decides
        # most rays of the later iterations (raytrace.TracedTile), once every tile has painted it ----
        first = run(traced, previous, 1, keep, beside=lambda: raytrace.thin_parts(scene, time, camera, grid, seen))
        parts = first
        if params.iterations > 1:
            kept = keep[1:] if keep is not None else None
            parts = then(first, iterate([p[0] for p in first], params.iterations - 1, kept))
    elif params.method == "raytrace":
        if seen is not None and not given:  # what the pixel centres see, in a pass of its own
            visible = grid.tiles(tile_rows(grid, threads))
            extra = on_tiles(lambda tile: _visible(scene, time, camera, tile, seen), [*visible, None])
        parts = iterate(previous, params.iterations, keep)
    else:
        # ---- the plain render, traced: iteration 1 of a new painting, the source of every lookup ----
        temporal = not previous.blank
        plain_keep = keep[:1] if keep is not None and not temporal else None
        plain_parts = run(traced, PaintState.canvas(region), 1, plain_keep)
        plain = PaintState.joined([p[0] for p in plain_parts], region)
        # ---- the later iterations (all of them in temporal mode), looked up tile by tile ----
        start = previous if temporal else plain
        lookups = params.iterations if temporal else params.iterations - 1
        kept = (keep if temporal else keep[1:]) if keep is not None else None
        looked = run(
            lambda tile: imagespace.tile_iteration(plain, setup_tile(camera, tile, params), params, frame.looks),
            start,
            lookups,
            kept,
        )
        parts = then(plain_parts, looked)
    state = PaintState.joined([p[0] for p in parts], region)
    return PaintResult(state, total([p[1] for p in parts] + extra), keep or [])


def seen_grid(scene: Scene, time: float, camera: Camera, width: int, height: int, params: PaintParams) -> Region | None:
    """The image whose pixel centres decide most rays of a ``width x height`` painting (:func:`uses_seen`),
    None when every ray is traced. At several samples it is twice as fine: it sees the
    thin geometry that the samples antialias."""
    if not uses_seen(params, camera) or scene.geometry(time)[1] is None:
        return None
    fine = 1 if params.spp == 1 else 2
    return Region(fine * width, fine * height)


def see(scene: Scene, time: float, camera: Camera, rows: Region) -> kernels.Seen:
    """What the pixel centres of ``rows`` (full-width rows of a :func:`seen_grid`) see: that part of a
    painting's ``seen``, found apart (``kernels.Seen.joined`` puts the parts together)."""
    part = kernels.Seen.empty(rows.width, rows.height)
    raytrace.visible_faces(scene, time, camera, rows, part)
    raytrace.thin_parts(scene, time, camera, rows, part)
    return part


def uses_seen(params: PaintParams, camera: Camera) -> bool:
    """Whether paintings with these settings decide rays by what the pixel centres see
    (``kernels.resolve_seen``), in a scene with triangles: with ``fast``, traced, eyes at rest (every ray
    of an eye starts at its point: not omnidirectional stereo, ``Camera.one_eye_point``) and targets that
    move (else every iteration casts the first one's rays, and the exact painting costs nothing more), and
    more than one ray a pixel. Not the region's size: a tile must be a crop."""
    looks = params.looks()
    eyes_rest = all(look.lambda_e == 0.0 for look in looks)
    fast = params.fast and params.method == "raytrace" and eyes_rest and any(look.lambda_p != 0.0 for look in looks)
    return fast and camera.one_eye_point and params.iterations * params.spp > 1


def _visible(scene: Scene, time: float, camera: Camera, tile: Region | None, seen: kernels.Seen) -> dict[str, float]:
    """:func:`raytrace.visible_faces` of one tile of the grid into ``seen`` (None: where its thin parts lie,
    over the whole grid, :func:`raytrace.thin_parts`); its seconds."""
    watch = Stopwatch()
    with watch.stage("intersect"):
        if tile is None:
            raytrace.thin_parts(scene, time, camera, Region(seen.width, seen.height), seen)
        else:
            raytrace.visible_faces(scene, time, camera, tile, seen.rows(tile))
    return watch.seconds
