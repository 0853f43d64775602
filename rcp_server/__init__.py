"""rcp: Recursive Camera Painting as a service (the engine: scenes, the recursion, the CLI)."""

import os

# Tiles are the parallelism; BLAS threads would only spin beside them (seen in perf as blas_thread_server
# taking a core's share during painting). Must be set before numpy loads OpenBLAS.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

# ruff: noqa: E402 (the imports below must come after the settings above)

from .camera import Camera, Region
from .mappings import MappingInput, register_mapping
from .painting import PaintResult, PaintState, paint
from .params import PaintParams
from .scenefile import SceneError, load_scene

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
