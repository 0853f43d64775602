"""The recursion ``I_n = F(I_{n-1}, S(n))``: previous per-pixel data -> per-pixel cameras -> new data.

The loop owns the painting, as pbrt-v4's ``ImageTileIntegrator::Render`` owns its tiles: :func:`paint` builds
the :class:`Job`, asks the method for its :class:`Pass` es, and runs each on every tile (:class:`TileLoop`). A
method only plans passes; what evaluates one tile's iteration is the pass's ``tiles``: traced
(``raytrace.TracedTiles``) or looked up in the plain render (``imagespace.LookupTiles``), both lending the same
tile interface (``paintstate.TileIteration``). Each iteration has the four stages of ``stopwatch.STAGES``,
timed separately.

A pixel reads only its own previous value, so the image splits into tiles that run every iteration
independently: tiles go to threads, and a tile gives exactly the pixels of the same region of a full
render. ``I_0`` is mid-grey and moves no ray, so iteration 1 is the plain ray-traced image.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ThreadPoolExecutor
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from functools import partial
from typing import Protocol

import numpy as np

from ..camera.camera import Camera, Region
from ..engine.paintstate import Abandoned, PaintState, TileIteration
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util.stopwatch import STAGES, Stopwatch, total
from . import stereo
from .frame import Frame
from .imagespace import LookupTiles
from .raytrace import TracedTiles
from .workspace import Workspace

__all__ = [
    "STAGES",
    "Abandoned",
    "PaintResult",
    "PaintState",
    "TILE_WORK",
    "Workspace",
    "default_threads",
    "paint",
    "tile_rows",
]


@dataclass
class PaintResult:
    """What :func:`paint` returns: the last iteration's ``state`` (pass it as ``previous`` to continue in
    temporal mode), ``stage_seconds`` (thread time by stage, summed over tiles and iterations) and, when
    ``keep_iterations`` was asked, ``iterations``: each iteration's image, (h, w, 3) float32 in [0, 1]."""

    state: PaintState
    stage_seconds: dict[str, float]  # summed over tiles (thread time), all iterations
    iterations: list[np.ndarray] = field(default_factory=list)  # (h, w, 3) per iteration when kept

    @property
    def image(self) -> np.ndarray:
        """The painting, (h, w, 3) float32 in [0, 1]."""
        return self.state.image()


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
    workspace: Workspace | None = None,
) -> PaintResult:
    """Paint ``region`` (default: all) of a ``width x height`` image of ``scene`` seen by ``camera`` (a stereo
    camera's painting holds both eyes' images: ``camera.image_size`` of one eye's).

    Per-frame mode: ``previous=None`` starts from ``I_0`` and runs ``params.iterations`` iterations.
    Temporal mode: pass the previous frame's :attr:`PaintResult.state` to continue the recursion from it
    with this frame's camera and time (it must cover the same region; otherwise the canvas restarts).

    Tiles run on ``pool`` when given (a server shares one pool between all its paintings, so their tiles
    queue for the same cores; pass its size as ``threads``), else on a pool of this call's own. ``should_stop`` is
    asked before every iteration of every tile; once it says yes the painting raises :class:`Abandoned`.

    ``workspace``: the buffers to paint in (:class:`workspace.Workspace`), kept by a caller that paints many
    frames; the result then lives until the painting after next on it.
    """
    job = Job.of(
        scene, camera, width, height, params, time, previous, region, threads, keep_iterations, pool, should_stop,
        workspace or Workspace(),
    )  # fmt: skip
    loop = TileLoop(job)
    seconds: list[dict[str, float]] = []
    for step in METHODS[params.method](job):
        seconds += loop.run(step)
    return PaintResult(job.result, total(seconds), job.keep or [])


def check(scene: Scene, camera: Camera, width: int, height: int, params: PaintParams, region: Region) -> None:
    """Every reason not to paint ``region`` of a ``width x height`` painting with these settings: ValueError
    (or ``CameraError``) saying which."""
    camera.check_painting(width, height)
    full = Region(width, height)
    if (region.full_width, region.full_height) != (width, height):
        raise ValueError("region belongs to an image of another size")
    if params.method == "image" and region != full:
        raise ValueError("the image-space method needs the full image: its lookups reach anywhere on screen")
    shared = camera.eyes == "shared" and camera.stereo != "mono"
    if shared and (region != full or params.method != "raytrace"):
        raise ValueError("eyes that share their smudges are traced, over the whole painting (the right reads the left)")
    scene.check_names(params)


@dataclass
class Job:
    """One painting as the tile loop runs it: what :func:`check` let through, and what every method reads."""

    scene: Scene
    camera: Camera
    width: int
    height: int
    params: PaintParams
    time: float
    region: Region
    previous: PaintState | None  # I_{n-1} of the first iteration; None: the canvas I_0
    threads: int
    pool: Executor | None
    should_stop: Callable[[], bool] | None
    frame: Frame  # the scene as every tile's kernels take it, once
    tiles: list[Region]
    keep: list[np.ndarray] | None  # (h, w, 3) float32 per iteration, when kept
    workspace: Workspace
    result: PaintState  # where each tile's last iteration goes
    shared: bool  # the eyes share their smudges

    @classmethod
    def of(
        cls, scene, camera, width, height, params, time, previous, region, threads, keep_iterations, pool,
        should_stop, workspace,
    ) -> Job:  # fmt: skip
        """The job of :func:`paint`'s arguments, checked."""
        full = Region(width, height)
        region = region or full
        check(scene, camera, width, height, params, region)
        if keep_iterations and region != full:
            raise ValueError("keep_iterations needs the full image")
        if previous is not None and (previous.region != region or previous.blank):
            previous = None  # another region: the canvas restarts
        threads = threads or default_threads()
        return cls(
            scene=scene,
            camera=camera,
            width=width,
            height=height,
            params=params,
            time=time,
            region=region,
            previous=previous,
            threads=threads,
            pool=pool,
            should_stop=should_stop,
            frame=Frame.of(scene, time, camera, params, width, height, threads=threads, whole=region == full),
            tiles=region.tiles(tile_rows(region, threads, params.spp * params.iterations)),
            keep=[np.empty((height, width, 3), np.float32) for _ in range(params.iterations)]
            if keep_iterations
            else None,
            workspace=workspace,
            result=workspace.result(region, params.reads(), keep=previous),
            shared=camera.eyes == "shared" and camera.stereo != "mono",
        )


class Tiles(Protocol):
    """What evaluates one tile's iteration (pbrt-v4's ``EvaluatePixelSample``, a tile at a time): for a pass,
    the tile's iteration with its buffers, lent for the ``with`` block. ``reads``: the tile's rows of what the
    displacement fields read instead of the tile's own state (the eyes of a stereo painting sharing smudges)."""

    def lend(self, tile: Region, reads: PaintState | None) -> AbstractContextManager[TileIteration]: ...


@dataclass(frozen=True)
class Pass:
    """One run of the tile loop: ``iterations`` iterations of every tile by ``tiles``, from ``start``'s rows
    (None: the canvas ``I_0``), the last into ``into``'s rows. ``keep``: full images, one per iteration, that
    get each iteration's color; ``reads``: what the fields read instead of each tile's own state."""

    tiles: Tiles
    start: PaintState | None
    iterations: int
    into: PaintState
    keep: list[np.ndarray] | None = None
    reads: PaintState | None = None


def traced(job: Job) -> Iterator[Pass]:
    """The traced method's passes: every iteration of every tile in one pass. With shared eyes, one pass an
    iteration, each reading what the eyes share of the one before (``stereo.shared_sources``)."""
    tiles = TracedTiles(job.frame, job.camera, job.params, job.workspace, job.tiles, keeps_anchor=job.shared)
    if not job.shared:
        yield Pass(tiles, job.previous, job.params.iterations, job.result, job.keep)
        return
    sources: np.ndarray | None = None  # the pixel each pixel's fields read, found once
    for n in range(job.params.iterations):
        start = job.previous if n == 0 else job.result
        reads = None
        if start is not None:
            if sources is None:
                sources = stereo.shared_sources(job.scene, job.time, job.camera, job.region)
            reads = start.gathered(sources)
        keep = job.keep[n : n + 1] if job.keep is not None else None
        yield Pass(tiles, start, 1, job.result, keep, reads)


def image_space(job: Job) -> Iterator[Pass]:
    """The image-space method's passes: the plain render traced, then every later iteration looked up in it
    (in temporal mode every iteration looks up)."""
    plain = PaintState.empty(job.region, job.params.reads())
    temporal = job.previous is not None
    keep = job.keep
    # ---- the plain render, traced: iteration 1 of a new painting, the source of every lookup ----
    traced_tiles = TracedTiles(job.frame, job.camera, job.params, job.workspace, job.tiles)
    yield Pass(traced_tiles, None, 1, plain, keep[:1] if keep is not None and not temporal else None)
    # ---- the later iterations (all of them in temporal mode), looked up tile by tile ----
    lookups = job.params.iterations if temporal else job.params.iterations - 1
    kept = (keep if temporal else keep[1:]) if keep is not None else None
    looked_up = LookupTiles(plain, job.camera, job.params, job.frame.looks)
    yield Pass(looked_up, job.previous if temporal else plain, lookups, job.result, kept)


METHODS: dict[str, Callable[[Job], Iterator[Pass]]] = {"raytrace": traced, "image": image_space}
"""Each painting method (``PaintParams.method``) by name: the passes it plans for a job."""


class TileLoop:
    """Runs the passes of one painting over its tiles, on the pool: the one loop of every method."""

    def __init__(self, job: Job):
        self.job = job

    def run(self, step: Pass) -> list[dict[str, float]]:
        """Every tile of ``step``, on the painting's pool (or its own threads, or here): each tile's stage
        seconds."""
        job = self.job
        work = partial(self.tile, step)
        tiles = list(range(len(job.tiles)))
        if job.pool is not None:
            return list(job.pool.map(work, tiles))
        if job.threads == 1 or len(tiles) == 1:
            return [work(n) for n in tiles]
        with ThreadPoolExecutor(job.threads, thread_name_prefix="rcp-tile") as own:
            return list(own.map(work, tiles))

    def tile(self, step: Pass, n: int) -> dict[str, float]:
        """The pass's iterations of tile ``n``: its stage seconds."""
        tile, should_stop = self.job.tiles[n], self.job.should_stop
        state = PaintState.canvas(tile) if step.start is None else step.start.rows(tile)
        watch = Stopwatch()
        with step.tiles.lend(tile, None if step.reads is None else step.reads.rows(tile)) as iterate:
            for iteration in range(step.iterations):
                if should_stop is not None and should_stop():
                    raise Abandoned
                state = iterate(state, watch)
                with watch.stage("bookkeeping"):
                    if step.keep is not None:
                        state.paste_color(step.keep[iteration])
            with watch.stage("bookkeeping"):
                state.write_into(step.into.rows(tile))
        return watch.seconds
