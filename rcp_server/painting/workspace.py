"""The memory a painting works in, declared in one place: what each buffer costs a pixel, and the buffers
themselves, kept from one painting to the next when a caller paints many (a walk's frames).

A painting holds per pixel only its result (color and the channels it reads, :meth:`PaintParams.reads`),
the ink of outlines, and the picture. Everything an iteration works in (rays, hits, the two states it
alternates between, the points where surface noise is read) lives in :class:`TileBuffers`, lent to one tile
at a time: a painting needs as many as it runs tiles at once, whatever its size.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..camera.camera import RAY_DTYPE, Region
from ..engine import kernels
from ..engine.kernels import screencells
from ..engine.kernels.embree import Hits, packet_order
from ..engine.paintstate import CHANNELS, PaintState, channel_shape
from ..settings.params import PaintParams


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
            packets=np.empty(rays, np.int64),
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
            packets=packet_order(region.width, region.height, self.spp, s.packets),
            starts=s.starts[cut],
            todo=s.todo[cut],
            next_todo=s.next_todo[cut],
            queue=s.queue[:rays],
        )
        states = (self.states[0].first(n, region), self.states[1].first(n, region))
        return scratch, states, None if self.anchor is None else self.anchor[:n]


FLOAT = np.dtype(np.float32).itemsize


def channel_bytes(name: str) -> int:
    """Bytes a pixel of channel ``name`` takes in a state (float32 numbers)."""
    return FLOAT * int(np.prod(channel_shape(name, 1)[1:], dtype=np.int64))


def state_bytes(channels: frozenset[str]) -> int:
    """Bytes a pixel of a state recording color and ``channels`` takes."""
    return sum(channel_bytes(name) for name in CHANNELS if name == "color" or name in channels)


INK_BYTES = 1 + 4  # kernels.Ink: the edge grid uint8 and each pixel's distance float32
ANCHOR_BYTES = 3 * FLOAT  # where surface noise is read, the plain render's points, kept by a tile run in parts
ENCODED_BYTES = 3  # the picture as 8-bit RGB, before the encoder


def pixel_bytes(params: PaintParams, *, outlines: bool = False, shared: bool = False, kept: int = 1) -> dict[str, int]:
    """What one painted pixel costs with ``params``, buffer by buffer, bytes: ``kept`` result states (a walk
    in temporal mode holds two: the frame before and the one being painted), the ink when some material draws
    ``outlines``, the screen cells when the eyes rest, the anchor of surface noise when the eyes of a stereo
    painting are ``shared`` (its tiles run one iteration at a time), the 8-bit picture. Tile buffers are not
    counted: their size is the tiles', not the painting's. ``rcp bench memory`` prints these beside the
    measured slope."""
    reads = params.reads()
    costs = {
        "result": kept * state_bytes(reads),
        "ink": INK_BYTES if outlines else 0,
        "anchor": ANCHOR_BYTES if shared and "position" in reads else 0,
        "picture": ENCODED_BYTES,
        # the screen cells of eyes at rest (kernels.screencells), each eye's over its own pixels
        "screen": screencells.BYTES if all(look.lambda_e == 0.0 for look in params.looks()) else 0,
    }
    if params.method == "image":
        costs["plain"] = state_bytes(reads)
    return costs


class Workspace:
    """Buffers that paintings borrow and give back. A painting of its own makes one and drops it; a walk
    keeps one for its frames, so that a painting after the first allocates nothing of a pixel's size (the
    same results and tile buffers, as long as size and settings stay).

    A result lives until the painting after next on the same workspace: :meth:`result` never gives the
    arrays of the state it is asked to keep (the frame before, in temporal mode), and alternates two.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._free: list[TileBuffers] = []
        self._results: dict[tuple, list[PaintState]] = {}
        self.closed = False

    def close(self) -> None:
        """Drop every buffer now (a walk that ended): those a painting in progress uses go with it, once it stops;
        nothing is kept from then on."""
        with self._lock:
            self.closed = True
            self._free.clear()
            self._results.clear()

    @contextmanager
    def tile_buffers(self, capacity: int, spp: int, masked: bool, channels: frozenset[str]) -> Iterator[TileBuffers]:
        """Buffers for one tile of up to ``capacity`` pixels, lent for the ``with`` block."""
        with self._lock:
            fits = [
                b
                for b in self._free
                if b.capacity >= capacity
                and b.spp == spp
                and (len(b.scratch.todo) > 1 or not masked)
                and b.states[0].recorded() == frozenset(channels) | {"color"}
            ]
            buffers = fits[0] if fits else None
            if buffers is not None:
                self._free.remove(buffers)
            else:  # settings changed: the buffers that no longer fit go
                self._free = [b for b in self._free if b.capacity >= capacity and b.spp == spp]
        if buffers is None:
            buffers = TileBuffers.allocate(capacity, spp, masked, channels)
        try:
            yield buffers
        finally:
            with self._lock:
                if not self.closed:
                    self._free.append(buffers)

    def idle(self) -> list[TileBuffers]:
        """The tile buffers not lent now."""
        with self._lock:
            return list(self._free)

    def result(self, region: Region, channels: frozenset[str], keep: PaintState | None = None) -> PaintState:
        """A state of ``region`` recording color and ``channels`` to paint into, whose arrays are not ``keep``'s."""
        key = (region, channels)
        with self._lock:
            if self.closed:  # a painting that began as its walk ended: its own result, dropped with it
                return PaintState.empty(region, channels)
            pair = self._results.setdefault(key, [])
            if len(self._results) > 2:  # another size or other settings: the oldest go
                del self._results[next(iter(self._results))]
            if len(pair) < 2:
                pair.append(PaintState.empty(region, channels))
                return pair[-1]
            state = pair[0] if keep is None or pair[0].color is not keep.color else pair[1]
            # by identity (a state's == compares its arrays); the least recently given goes first next time
            pair[:] = [other for other in pair if other is not state] + [state]
            state.blank = False
            return state
