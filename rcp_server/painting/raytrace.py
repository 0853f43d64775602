"""The traced method: every iteration casts one ray per sample from its per-pixel camera into the scene.

A tile's iteration has three stages, a compiled kernel each (``kernels.paint_iteration``): camera assignment
(``assign.py``: the mapping turns ``I_{n-1}`` into displacements ``V_p, V_e``, and those into rays),
intersection (Embree, through ``kernels/embree.py``) and shading (``kernels.shade``).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial

import numpy as np

from ..camera.camera import Camera, Region
from ..engine import kernels
from ..engine.paintstate import PaintState, TileIteration
from ..settings.params import PaintParams
from ..util.stopwatch import Stopwatch
from .assign import TileSetup, cameras, setup_tile
from .frame import Frame
from .workspace import TileBuffers, Workspace


class TracedTile:
    """The traced iterations of one tile, ``I_{n-1} -> I_n`` (a ``paintstate.TileIteration``): set up once
    for the painting, each iteration one call of ``kernels.paint_iteration`` into one of the two
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
        kernels.paint_iteration(
            cast=cast,
            source=kernels.channels(source),
            out=kernels.channels(out),
            trace=self.frame.trace,
            shading=self.frame.shading,
            scratch=self.scratch,
            watch=watch,
        )
        if state.blank and out.position is not None:
            if self.keeps_anchor or self.anchor_store is None:
                self.anchor = out.position.copy()
            else:
                self.anchor = self.anchor_store
                self.anchor[...] = out.position
        return out


class TracedTiles:
    """The traced method's evaluator (``loop.Tiles``): each tile's iterations are a :class:`TracedTile`, set up
    once a painting and lent buffers of the painting's workspace for each pass.

    ``keeps_anchor``: the tiles run their iterations in several passes (the eyes of a stereo painting sharing
    their smudges), so each keeps the points where surface noise is read itself.
    """

    def __init__(
        self,
        frame: Frame,
        camera: Camera,
        params: PaintParams,
        workspace: Workspace,
        tiles: list[Region],
        keeps_anchor: bool = False,
    ):
        self.frame, self.camera, self.params, self.keeps_anchor = frame, camera, params, keeps_anchor
        self.painters: dict[Region, TracedTile] = {}
        capacity = max(tile.pixel_count for tile in tiles)
        self.buffers = partial(workspace.tile_buffers, capacity, params.spp, frame.trace.masked, params.reads())

    def painter(self, tile: Region) -> TracedTile:
        """The tile's traced iterations (the same over the passes of a painting)."""
        if tile not in self.painters:
            setup = setup_tile(self.camera, tile, self.params)
            self.painters[tile] = TracedTile(self.frame, setup, self.params, keeps_anchor=self.keeps_anchor)
        return self.painters[tile]

    @contextmanager
    def lend(self, tile: Region, reads: PaintState | None) -> Iterator[TileIteration]:
        painter = self.painter(tile)
        painter.source = reads
        with self.buffers() as buffers:
            painter.bind(buffers)
            yield painter
