"""rcp: Recursive Camera Painting as a service (the engine: scenes, the recursion, the CLI)."""

import os
from importlib import import_module
from typing import TYPE_CHECKING

# Tiles are the parallelism; BLAS threads would only spin beside them (seen in perf as blas_thread_server
# taking a core's share during painting). Must be set before numpy loads OpenBLAS.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

if TYPE_CHECKING:  # the names, for type checkers and the API reference; loaded on first use below
    from .camera.camera import Camera, Region
    from .painting.loop import PaintResult, PaintState, paint
    from .scene.scenefile import SceneError, load_scene
    from .settings.mappings import MappingInput, register_mapping
    from .settings.params import PaintParams

# where each public name lives: ``import rcp_server.engine...`` (a kernel compiled in a process of its own,
# ``engine/kernels/jit.py``) does not load trimesh and the painting loop for names it never uses
_PUBLIC = {
    "Camera": ".camera.camera",
    "Region": ".camera.camera",
    "PaintResult": ".painting.loop",
    "PaintState": ".painting.loop",
    "paint": ".painting.loop",
    "SceneError": ".scene.scenefile",
    "load_scene": ".scene.scenefile",
    "MappingInput": ".settings.mappings",
    "register_mapping": ".settings.mappings",
    "PaintParams": ".settings.params",
}


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(_PUBLIC[name], __name__), name)
    globals()[name] = value
    return value


__all__ = [
    "Camera",
    "MappingInput",
    "PaintParams",
    "PaintResult",
    "PaintState",
    "Region",
    "SceneError",
    "load_scene",
    "paint",
    "register_mapping",
]
