"""Compiling the kernels before anyone waits for them: the server does it in a thread while it already answers
(``service/state.py``), ``rcp compile`` when a container image is built.

numba compiles a kernel at its first call (``engine/kernels/jit.py``, ``cache=True``): about 25 s of one core
for all of them on a cold cache, a second or two to load them from a warm one. Painting a tiny image of each
scene calls every kernel a visitor's painting would, with the argument types that scene gives them (a new
type is a new compilation). The server compiles the first scene's (:func:`first_frame`, about 15 s of one
core) before it is ready, and the others' after (:func:`warm`).
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from dataclasses import replace

import numpy as np
from numba.core.registry import CPUDispatcher

from ..camera.camera import Camera
from ..engine.kernels import visibility
from ..scene.scene import Scene
from ..settings.params import PaintParams
from . import screen
from .loop import paint

SIZE = 16  # pixels a side: enough to reach every kernel, nothing more
ITERATIONS = 2  # the second iteration is the first that displaces cameras


def kernels() -> list[CPUDispatcher]:
    """The engine's compiled entry points as loaded: every numba kernel a module of ``rcp_server.engine`` defines,
    except those inlined into their callers (``inline="always"``), which are never compiled on their own. (The
    scene's own kernels compile as scenes load, before these.)"""
    found = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("rcp_server.engine.") and module is not None:
            for value in list(vars(module).values()):
                if (
                    isinstance(value, CPUDispatcher)
                    and value.py_func.__module__ == name
                    and value.targetoptions.get("inline") != "always"
                ):
                    found[id(value)] = value
    return list(found.values())


def compiled(entries: Iterable[CPUDispatcher]) -> int:
    """How many of ``entries`` have a compiled version in this process (compiled, or loaded from the cache;
    a kernel called only from inside another one counts when it was compiled for it, on a cold cache)."""
    return sum(len(kernel.overloads) > 0 for kernel in entries)  # len: safe while another thread compiles


def tiny(camera: Camera) -> tuple[int, int]:
    """The least painting ``camera`` can take that reaches every kernel."""
    return camera.image_size(2 * SIZE if camera.projection == "equirect" else SIZE, SIZE)


def first_frame(scene: Scene) -> None:
    """Paints a tiny image of ``scene`` with its own settings: after this its first walk frame compiles nothing
    (about half of all the kernels' compile time, the half a visitor waits for)."""
    paint(scene, scene.camera, *tiny(scene.camera), replace(scene.paint, iterations=ITERATIONS), threads=1)


def screen_cells(scene: Scene) -> None:
    """Builds the screen cells of a tiny image of ``scene`` and asks them a few rays: ``auto`` builds them only
    for large paintings, whose first one would otherwise wait for their compiler (about 10 s of one core)."""
    geometry, tracer = scene.geometry(0.0)
    camera = scene.camera.moved(projection="perspective", stereo="mono")
    if tracer is None:
        return
    built = screen.cells(camera, PaintParams(), SIZE, SIZE, geometry.triangles, mode="on")
    rays = np.arange(8)
    origins = np.repeat(np.asarray([camera.eye], np.float32), len(rays), axis=0)
    directions = np.repeat(np.asarray([camera.basis()[2]], np.float32), len(rays), axis=0)
    face = np.empty(len(rays), np.int32)
    visibility.find_faces(built, tracer.embree, origins, directions, rays, face, np.empty(len(rays), np.int64))


def warm(scenes: Iterable[Scene]) -> None:
    """Paints a tiny image of every scene with its own settings, and the image-space method once: after this the
    kernels a visitor's painting calls are compiled (and in numba's cache for the next process). A scene whose
    kernels are compiled already costs a few milliseconds."""
    first = True
    for scene in scenes:
        first_frame(scene)
        if first:  # the other projections, mappings and sample counts compile nothing more (measured)
            screen_cells(scene)
            paint(
                scene, scene.camera, *tiny(scene.camera), PaintParams(iterations=ITERATIONS, method="image"), threads=1
            )
            first = False
