"""rcp: Recursive Camera Painting as a service (the engine: scenes, the recursion, the CLI)."""

from .camera import Camera, Region
from .mappings import MappingInput, register_mapping
from .painting import PaintParams, PaintResult, PaintState, paint
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
