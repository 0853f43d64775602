"""How to paint: the painting settings, validated once at construction."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from .camera import Camera
from .mappings import get_mapping

METHODS = ("raytrace", "image")
"""How later iterations see their displaced targets: traced (right everywhere), or looked up in the plain
render (``imagespace.py``: fast, needs ``lambda_e = 0``, wrong off screen)."""
EDGES = ("clamp", "wrap", "mirror")
"""How the image method reads a lookup that falls off screen (the order is the kernel's code for each)."""


@dataclass(frozen=True)
class PaintParams:
    """How to paint. ``lambda_p`` in pixels, ``lambda_e`` in scene units; ``z0`` (focus depth) defaults to
    the distance from the eye to ``look_at``; ``z_max`` (depth of a miss) to the scene's size.
    ``method`` is one of :data:`METHODS`; ``edge`` (one of :data:`EDGES`) is how the image method reads
    off screen."""

    mapping: str = "color"
    eye_mapping: str = "color"
    iterations: int = 6
    spp: int = 1
    lambda_p: float = 8.0
    lambda_e: float = 0.0
    z0: float | None = None
    noise: float = 0.0
    seed: int = 0
    z_max: float | None = None
    method: str = "raytrace"
    edge: str = "mirror"

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"unknown method {self.method!r}; choose one of {', '.join(METHODS)}")
        if self.edge not in EDGES:
            raise ValueError(f"unknown edge mode {self.edge!r}; choose one of {', '.join(EDGES)}")
        get_mapping(self.mapping)
        get_mapping(self.eye_mapping)
        if self.iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {self.iterations}")
        if self.spp < 1:
            raise ValueError(f"spp (samples per pixel) must be at least 1, got {self.spp}")
        for name in ("lambda_p", "lambda_e", "z0", "noise", "z_max"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value}")
        if self.noise < 0:
            raise ValueError(f"noise must not be negative, got {self.noise}")
        if self.method == "image" and self.lambda_e != 0.0:
            raise ValueError(
                f"the image-space method cannot represent eye displacement (lambda_e = {self.lambda_e}): "
                "use lambda_e 0, or method raytrace"
            )

    @classmethod
    def from_dict(cls, values: dict) -> PaintParams:
        known = {f.name for f in fields(cls)}
        unknown = set(values) - known
        if unknown:
            raise ValueError(f"unknown paint settings {sorted(unknown)}; known: {sorted(known)}")
        return cls(**values)

    def focus(self, camera: Camera) -> float:
        """``z0``: the focus depth given, or the view depth of the camera's look-at point."""
        return self.z0 if self.z0 is not None else float(np.linalg.norm(np.subtract(camera.look_at, camera.eye)))

    def reads(self) -> frozenset[str]:
        """The channels of ``I_{n-1}`` this painting reads (the only ones it records)."""
        channels = get_mapping(self.mapping).reads
        if self.lambda_e != 0.0:
            channels |= get_mapping(self.eye_mapping).reads
        return channels
