"""A walker's move in a scene at a moment: the collision of engine/collide.py with the scene's geometry."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..engine.collide import Body, body_at, collide, standing
from .scene import Scene


class Step(NamedTuple):
    """Where a move ends (eye (3,) float64, scene units), the body that kept it clear, and whether it stands."""

    eye: np.ndarray
    body: Body
    standing: bool


def walk(scene: Scene, time: float, eye, delta, height: float | None = None) -> Step:
    """The eye at ``eye`` moved by ``delta`` through ``scene`` at ``time`` as a walker whose eye is ``height``
    above its floor (None: measured at ``eye``); its radius scales with that height, within the scene's size."""
    geometry, tracer = scene.geometry(time)
    if tracer is None:  # nothing to walk into
        return Step(np.add(eye, delta, dtype=np.float64), Body(radius=0.0, height=None, step=0.0), False)
    lo, hi = geometry.bounds
    body = body_at(tracer, eye, max(float(np.linalg.norm(hi - lo)), 1e-6), height)
    end = collide(tracer, eye, delta, body)
    return Step(end, body, standing(tracer, end, body))
