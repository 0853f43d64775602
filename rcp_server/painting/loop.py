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
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ThreadPoolExecutor
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field
from functools import partial
from typing import Protocol

import numpy as np

from ..camera.camera import Camera, Region
from ..engine.paintstate import Abandoned, PaintState, TileIteration
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util.stopwatch import STAGES, Stopwatch, total
from . import imagespace, raytrace, stereo
from .raytrace import setup_tile
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
    state: PaintState
    stage_seconds: dict[str, float]  # summed over tiles (thread time), all iterations
    iterations: list[np.ndarray] = field(default_factory=list)  # (h, w, 3) per iteration when kept

    @property
    def image(self) -> np.ndarray:
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
    method: Method = ImageSpace(job) if params.method == "image" else Traced(job)
    seconds = method.paint(TileLoop(job))
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
    frame: raytrace.Frame  # the scene as every tile's kernels take it, once
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
            frame=raytrace.Frame.of(scene, time, camera, params, width, height),
            tiles=region.tiles(tile_rows(region, threads, params.spp * params.iterations)),
            keep=[np.empty((height, width, 3), np.float32) for _ in range(params.iterations)]
            if keep_iterations
            else None,
            workspace=workspace,
            result=workspace.result(region, params.reads(), keep=previous),
            shared=camera.eyes == "shared" and camera.stereo != "mono",
        )


class Method(Protocol):
    """A way to paint (as pbrt-v4's integrators plug into ``ImageTileIntegrator::Render``): the iteration of
    each tile that the loop runs, lent its buffers for a run, and the runs a whole painting takes."""

    def lend(self, tile: Region) -> AbstractContextManager[TileIteration]: ...

    def paint(self, loop: TileLoop) -> list[dict[str, float]]: ...


class TileLoop:
    """Runs a method's iterations over the tiles of one painting, on the pool: the one loop of every method."""

    def __init__(self, job: Job):
        self.job = job

    def map(self, work: Callable, items: list) -> list:
        """``work`` of every item, on the painting's pool (or its own threads, or here)."""
        job = self.job
        if job.pool is not None:
            return list(job.pool.map(work, items))
        if job.threads == 1 or len(items) == 1:
            return [work(item) for item in items]
        with ThreadPoolExecutor(job.threads, thread_name_prefix="rcp-tile") as own:
            return list(own.map(work, items))

    def run(
        self,
        method: Method,
        start: PaintState | None,
        iterations: int,
        keep: list[np.ndarray] | None,
        into: PaintState | None = None,
        beside: Callable[[], None] | None = None,
    ) -> list[dict[str, float]]:
        """Every tile: ``iterations`` of ``method`` from ``start``'s rows (None: the canvas), the last into
        ``into``'s rows (default the painting's result); each tile's stage seconds. ``beside``: a job for the
        same pool at the same time, started first, on a core of its own, so that it ends with the tiles
        (queued last, it ran alone once they were done, the other cores idle)."""
        work = partial(self.tile, method, start, iterations, keep, self.job.result if into is None else into)
        tiles = list(range(len(self.job.tiles)))
        if beside is None:
            return self.map(work, tiles)
        return self.map(partial(_beside_first, beside, work), [None, *tiles])[1:]

    def tile(
        self,
        method: Method,
        start: PaintState | None,
        iterations: int,
        keep: list[np.ndarray] | None,
        into: PaintState,
        n: int,
    ) -> dict[str, float]:
        """``iterations`` iterations of tile ``n``: its stage seconds. ``keep`` (full images, one per iteration)
        gets each iteration's color at the tile's rows."""
        tile, should_stop = self.job.tiles[n], self.job.should_stop
        state = PaintState.canvas(tile) if start is None else start.rows(tile)
        watch = Stopwatch()
        with method.lend(tile) as iterate:
            for iteration in range(iterations):
                if should_stop is not None and should_stop():
                    raise Abandoned
                state = iterate(state, watch)
                with watch.stage("bookkeeping"):
                    if keep is not None:
                        state.paste_color(keep[iteration])
            with watch.stage("bookkeeping"):
                state.write_into(into.rows(tile))
        return watch.seconds


def _beside_first(beside: Callable[[], None], work: Callable[[int], dict[str, float]], n: int | None):
    """``beside()`` for the item None, else ``work(n)``."""
    if n is None:
        beside()
        return None
    return work(n)


class Traced:
    """Every ray traced: each tile's iterations are a :class:`raytrace.TracedTile`, set up once a painting.
    With shared eyes, one iteration at a time over the whole painting, each reading what the eyes share of
    the one before."""

    def __init__(self, job: Job):
        self.job = job
        self.painters: dict[Region, raytrace.TracedTile] = {}
        self.sources: np.ndarray | None = None  # with shared eyes: the pixel each pixel's fields read
        reads = job.params.reads()
        capacity = max(tile.pixel_count for tile in job.tiles)
        self.buffers = partial(job.workspace.tile_buffers, capacity, job.params.spp, job.frame.trace.masked, reads)

    def painter(self, tile: Region) -> raytrace.TracedTile:
        """The tile's traced iterations (the same over the runs of a painting)."""
        if tile not in self.painters:
            job = self.job
            setup = setup_tile(job.camera, tile, job.params)
            self.painters[tile] = raytrace.TracedTile(job.frame, setup, job.params, keeps_anchor=job.shared)
        return self.painters[tile]

    @contextmanager
    def lend(self, tile: Region) -> Iterator[TileIteration]:
        painter = self.painter(tile)
        with self.buffers() as buffers:
            painter.bind(buffers)
            yield painter

    def paint(self, loop: TileLoop) -> list[dict[str, float]]:
        return self.iterate(loop, self.job.previous, self.job.params.iterations, self.job.keep)

    def iterate(
        self, loop: TileLoop, start: PaintState | None, iterations: int, keep: list[np.ndarray] | None
    ) -> list[dict[str, float]]:
        """``iterations`` traced iterations of every tile from ``start`` (None: the canvas) into the result."""
        job = self.job
        if not job.shared:
            return loop.run(self, start, iterations, keep)
        seconds: list[dict[str, float]] = []
        for n in range(iterations):
            states = start if n == 0 else job.result
            source = None
            if states is not None:
                if self.sources is None:
                    self.sources = stereo.shared_sources(job.scene, job.time, job.camera, job.region)
                source = states.gathered(self.sources)
            for tile in job.tiles:
                self.painter(tile).source = source.rows(tile) if source is not None else None
            seconds += loop.run(self, states, 1, keep[n : n + 1] if keep is not None else None)
        return seconds


class ImageSpace:
    """The image-space method: the plain render traced, every later iteration looked up in it tile by tile
    (``imagespace.tile_iteration``); in temporal mode every iteration looks up."""

    def __init__(self, job: Job):
        self.job = job
        self.plain = PaintState.empty(job.region, job.params.reads())

    @contextmanager
    def lend(self, tile: Region) -> Iterator[TileIteration]:
        job = self.job
        yield imagespace.tile_iteration(
            self.plain, setup_tile(job.camera, tile, job.params), job.params, job.frame.looks
        )

    def paint(self, loop: TileLoop) -> list[dict[str, float]]:
        job = self.job
        temporal = job.previous is not None
        keep = job.keep
        # ---- the plain render, traced: iteration 1 of a new painting, the source of every lookup ----
        plain = loop.run(Traced(job), None, 1, keep[:1] if keep is not None and not temporal else None, into=self.plain)
        # ---- the later iterations (all of them in temporal mode), looked up tile by tile ----
        start = job.previous if temporal else self.plain
        lookups = job.params.iterations if temporal else job.params.iterations - 1
        kept = (keep if temporal else keep[1:]) if keep is not None else None
        return plain + loop.run(self, start, lookups, kept)
