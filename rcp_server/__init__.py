"""rcp: Recursive Camera Painting as a service (the engine: scenes, the recursion, the CLI)."""

import os

# Tiles are the parallelism; BLAS threads would only spin beside them (seen in perf as blas_thread_server
# taking a core's share during painting). Must be set before numpy loads OpenBLAS.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

# ruff: noqa: E402 (the imports below must come after the settings above)

from .camera.camera import Camera, Region
from .painting.loop import PaintResult, PaintState, paint
from .scene.scenefile import SceneError, load_scene
from .settings.mappings import MappingInput, register_mapping
from .settings.params import PaintParams

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
