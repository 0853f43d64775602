"""The actor: one Ray worker's painter, holding the scenes it paints warm and each temporal band's last paintings.

Workers are Ray actors that hold the scenes they paint warm: a scene's arrays are put in the object store
once, and each actor builds its BVH itself (an Embree handle cannot travel). What a frame needs (camera,
time, the settings of its paintings) is a few hundred bytes; what comes back is the frame as uint8, 3 bytes a pixel.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass, fields

import numpy as np

from ..camera.camera import Camera, Region
from ..painting.loop import PaintState, paint
from ..painting.sequence import Looks, paint_looks
from ..scene.scene import Scene
from ..settings.params import PaintParams
from ..util import images
from .connection import ray_module

WARM_SCENES = 4  # scenes each actor keeps built (and the driver keeps in the object store)
KEPT_STATES = 4  # temporal states each band keeps (frames in flight and the one before): a frame can be asked again


# ---- the scene as it travels ----


def portable(scene: Scene) -> dict:
    """What a scene is, without what it caches (BVHs, locks): its public fields, as ``Scene(**fields)``."""
    return {f.name: getattr(scene, f.name) for f in fields(scene) if not f.name.startswith("_")}


@dataclass(frozen=True)
class Held:
    """A scene in the object store: ``key`` names it to the actors, ``ref`` (in a list, so that Ray hands it
    over unread) is fetched only by an actor that does not hold the scene warm yet."""

    key: str
    ref: list


class HeldScenes:
    """The scenes this driver keeps in the object store (the last ``most``, the most recently used last): each put
    there once, under a key of its own, for every kind of painting on Ray (films, large paintings, walkers) alike.
    Forgotten as a whole when Ray is joined again (:meth:`clear`): what an earlier join held is gone."""

    def __init__(self, most: int = WARM_SCENES):
        self.most = most
        self._held: OrderedDict[int, tuple[Scene, Held]] = OrderedDict()
        self._lock = threading.Lock()
        self._serial = itertools.count(1)

    def hold(self, scene: Scene) -> Held:
        """``scene`` in the object store, put there once."""
        with self._lock:
            entry = self._held.get(id(scene))
            if entry is None or entry[0] is not scene:
                held = Held(f"scene-{next(self._serial)}", [ray_module().put(portable(scene))])
                entry = self._held[id(scene)] = (scene, held)
                while len(self._held) > self.most:
                    self._held.popitem(last=False)
            self._held.move_to_end(id(scene))
            return entry[1]

    def clear(self) -> None:
        with self._lock:
            self._held.clear()


class WarmScenes:
    """The scenes an actor keeps built (their trees too), the most recently used last, at most ``most``."""

    def __init__(self, most: int):
        self.most = most
        self.built: OrderedDict[str, Scene] = OrderedDict()

    def get(self, held: Held) -> Scene:
        """``held``'s scene, built here the first time it is asked for."""
        scene = self.built.get(held.key)
        if scene is None:
            scene = Scene(**ray_module().get(held.ref[0]))
            scene.geometry(0.0)
            self.built[held.key] = scene
            while len(self.built) > self.most:
                self.built.popitem(last=False)
        self.built.move_to_end(held.key)
        return scene


class LostState(RuntimeError):
    """A temporal band's previous frame is gone: its actor died and Ray restarted it empty."""


class Painter:
    """One Ray actor's work: paints frames, or bands of rows, of the scenes it holds warm.

    Scenes are built here (BVH included) on first use and kept for the next call, the last ``WARM_SCENES``;
    ``previous`` keeps the last ``KEPT_STATES`` paintings of each temporal band this actor paints (by job and
    frame), so a band's recursion continues here, frame after frame, with nothing sent back and forth but the
    band's pixels, and a frame asked again (after another worker was lost) is painted again the same."""

    def __init__(self, threads: int):
        self.threads = threads
        self.scenes = WarmScenes(WARM_SCENES)
        self.previous: dict[tuple[str | None, Region], dict[int, PaintState]] = {}

    def _scene(self, held: Held) -> Scene:
        return self.scenes.get(held)

    def warm(self, held: Held) -> bool:
        """Build ``held``'s scene now, before the first frame waits for it."""
        self._scene(held)
        return True

    def frame(self, held: Held, shot: tuple[Camera, float], width: int, height: int, looks: Looks):
        """A whole frame from ``I_0``, painted with its ``looks`` (``sequence.frame_looks``): (height, width, 3)
        uint8."""
        camera, time = shot
        scene = self._scene(held)

        def paint_frame(camera: Camera, time: float, params: PaintParams, previous: PaintState | None):
            return paint(scene, camera, width, height, params, time=time, threads=self.threads)

        return images.to_uint8(paint_looks(paint_frame, camera, time, looks, None).image)

    def band(
        self,
        held: Held,
        job: str | None,
        region: Region,
        index: int,
        shot: tuple[Camera, float],
        looks: Looks,
    ) -> np.ndarray:
        """The rows of ``region`` of frame ``index``, painted with its ``looks``: from ``I_0`` for frame 0, else
        continuing from this band's painting of ``job``'s frame ``index - 1`` (kept when ``job`` is given):
        (rows, width, 3) uint8."""
        camera, time = shot
        scene = self._scene(held)
        previous = None
        if index > 0:
            previous = self.previous.get((job, region), {}).get(index - 1)
            if previous is None:
                raise LostState(f"a Ray worker was lost mid-job, and with it a band's frame {index - 1}")

        def paint_band(camera: Camera, time: float, params: PaintParams, previous: PaintState | None):
            return paint(
                scene, camera, region.full_width, region.full_height, params, time=time, previous=previous,
                region=region, threads=self.threads,
            )  # fmt: skip

        result = paint_looks(paint_band, camera, time, looks, previous)
        if job is not None:
            states = self.previous.setdefault((job, region), {})
            states[index] = result.state
            for old in [k for k in states if k <= index - KEPT_STATES]:
                del states[old]
        return images.to_uint8(result.image)

    def painted(self, job: str, region: Region) -> list[int]:
        """The frames of ``job`` whose band ``region`` this actor holds, to go on from."""
        return sorted(self.previous.get((job, region), {}))

    def forget(self, job: str) -> None:
        self.previous = {key: states for key, states in self.previous.items() if key[0] != job}

    def pid(self) -> int:
        return os.getpid()
