"""The walk actor: one walk-through's painter on a Ray worker, holding its scene and its temporal state.

A walk-through on Ray is held by one actor. It keeps the scene warm (its BVH built once) and the last frame's
per-pixel state, so a frame sends only the camera, the size and the settings (a few hundred bytes) and
returns only the JPEG, encoded here on the worker. Temporal mode continues from the state kept here, but only
from the frame the walk-through showed last (``after``): a state that is not that one (a frame the session
threw away, an actor started afresh after a loss) starts the recursion again from ``I_0``, as the threads
do when they have no state.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import time
from dataclasses import dataclass

import numpy as np

from ..camera.camera import Camera, Region
from ..painting.loop import PaintState, paint
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util import images
from .actor import Held, WarmScenes
from .connection import ray_module

WALK_SCENES = 2  # scenes a walk actor keeps built: the one shown and the one just left


@dataclass(frozen=True)
class Band:
    """One band of a walk frame, painted and encoded by one worker: rows ``[y, y + rows)`` of the painting as a JPEG
    of its own (the server forwards it as it is), and what the worker spent on it; ``span``: when the worker began
    and ended it (its wall clock, ``time.time()``: on one machine, the bench tells Ray's round trip apart from a band
    waiting for a core)."""

    y: int
    rows: int
    jpeg: bytes
    continued: bool
    paint_s: float
    cpu_s: float
    pixels: np.ndarray | None = None
    node: str = ""  # the Ray node that painted it
    span: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class Painted:
    """One walk frame, painted and encoded.

    jpeg : the encoded frame (empty when it came in bands); bands : its bands, each encoded on its own worker, top
    to bottom (empty when it is one JPEG); width, height : the painting's size in pixels (both eyes of a stereo
    pair); serial : the frame whose state the workers keep (None: painted on the server, the state is the
    session's); continued : it went on from the last frame's state (temporal), rather than from ``I_0``; paint_s :
    wall seconds painting and encoding on the workers (the slowest band); cpu_s : CPU seconds the workers' processes
    spent on it (every thread, every band); pixels : (height, width, 3) uint8, the painting before encoding, when
    asked for (tests); seconds : the frame's time as the server saw it (its round trip on Ray), what the walk's
    planner times."""

    jpeg: bytes
    width: int
    height: int
    serial: int | None
    continued: bool
    paint_s: float
    cpu_s: float
    pixels: np.ndarray | None = None
    seconds: float = 0.0
    bands: tuple[Band, ...] = ()


def joined(bands: list[Band], width: int, height: int, serial: int, seconds: float) -> Painted:
    """The frame of ``bands`` (top to bottom): one band's JPEG is the frame's; several travel as they are."""
    pixels = None
    if all(band.pixels is not None for band in bands):
        pixels = np.concatenate([band.pixels for band in bands], axis=0)
    one = len(bands) == 1
    return Painted(
        bands[0].jpeg if one else b"",
        width,
        height,
        serial,
        all(band.continued for band in bands),
        max(band.paint_s for band in bands),
        sum(band.cpu_s for band in bands),
        pixels,
        seconds,
        () if one else tuple(dataclasses.replace(band, pixels=None) for band in bands),
    )


class WalkPainter:
    """A Ray actor that paints one walk-through's frames, or one band of rows of them (``threads`` threads)."""

    def __init__(self, threads: int):
        self.threads = threads
        self.scenes = WarmScenes(WALK_SCENES)
        self.serial: int | None = None  # the frame whose state is kept
        self.region: Region | None = None  # the band of it
        self.state: PaintState | None = None
        self.node = ray_module().get_runtime_context().get_node_id()

    def _scene(self, held: Held) -> Scene:
        return self.scenes.get(held)

    def warm(self, held: Held) -> int:
        """Build ``held``'s scene now and paint a tiny frame of it (the compiled kernels load in this process),
        before the first frame waits for them; the process id."""
        scene = self._scene(held)
        paint(scene, scene.camera, 8, 8, PaintParams(iterations=2), threads=1)
        return os.getpid()

    def band(
        self,
        held: Held,
        camera: Camera,
        region: Region,
        params: PaintParams,
        scene_time: float,
        quality: int,
        serial: int,
        after: int | None,
        keep_pixels: bool = False,
    ) -> Band:
        """Rows ``region`` of frame ``serial`` (the painting's size: ``region.full_width x full_height``, both
        eyes): painted from this band's state of frame ``after`` when this actor keeps it (temporal), else from
        ``I_0``; encoded as JPEG at ``quality``."""
        began = time.time()
        wall, cpu = time.perf_counter(), time.process_time()
        width, height = region.full_width, region.full_height
        whole = region == Region(width, height)
        kept = self.region
        # a whole frame goes on from a whole frame of any size (resized); a band only from the same band
        same = kept == region or (whole and kept is not None and kept == Region(kept.full_width, kept.full_height))
        continued = after is not None and self.serial == after and same and self.state is not None
        previous = None
        if continued and self.state is not None:
            previous = self.state.resized(width, height) if whole else self.state
        result = paint(
            self._scene(held),
            camera,
            width,
            height,
            params,
            time=scene_time,
            previous=previous,
            region=None if whole else region,
            threads=self.threads,
        )
        self.serial, self.region, self.state = serial, region, result.state
        pixels = images.to_uint8(result.image)
        jpeg = images.encode(pixels, "JPEG", quality)
        return Band(
            region.y0,
            region.height,
            jpeg,
            continued,
            time.perf_counter() - wall,
            time.process_time() - cpu,
            pixels if keep_pixels else None,
            self.node,
            (began, time.time()),
        )

    def packed(self, frame: bytes, held: Held | None = None) -> Band:
        """:meth:`band`, its arguments pickled together by the caller (:func:`pack`, the scene by its key): one
        argument costs Ray less to send than nine. ``held``: the scene itself (Ray counts its reference), sent only
        when this actor's last scene was another one (it keeps its last scenes built)."""
        key, *args = pickle.loads(frame)
        if held is None and key not in self.scenes.built:
            raise LookupError(f"the walk actor does not hold scene {key}")
        return self.band(held or Held(key, []), *args)

    def frame(
        self,
        held: Held,
        camera: Camera,
        width: int,
        height: int,
        params: PaintParams,
        scene_time: float,
        quality: int,
        serial: int,
        after: int | None,
        keep_pixels: bool = False,
    ) -> Painted:
        """Frame ``serial`` whole (one band): see :meth:`band`."""
        band = self.band(held, camera, Region(width, height), params, scene_time, quality, serial, after, keep_pixels)
        return joined([band], width, height, serial, 0.0)

    def pid(self) -> int:
        return os.getpid()


def pack(
    key: str,
    camera: Camera,
    region: Region,
    params: PaintParams,
    scene_time: float,
    quality: int,
    serial: int,
    after: int | None,
    keep_pixels: bool,
) -> bytes:
    """:meth:`WalkPainter.band`'s arguments, the scene by its ``key``, as :meth:`WalkPainter.packed` takes them."""
    from ray import cloudpickle  # a registered mapping travels by value, as Ray would send it

    return cloudpickle.dumps((key, camera, region, params, scene_time, quality, serial, after, keep_pixels))
