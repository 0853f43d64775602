"""Walking, not flying: a camera's move checked against the scene's surfaces with a few Embree rays.

The walker is a body under its eye: a sphere of ``radius`` around the eye that no surface enters, and, when
there is a floor beneath, legs of ``height`` (the eye's height above the floor it stands on) that step up any
rise up to ``step`` and are stopped by anything higher. World +y is up (shared/MISSION.md). A move is applied
in three stages, each a handful of rays:

* **slide**: the horizontal part of the move (the whole move for a body with no floor) is swept from the eye,
  the knee (``step`` above the floor) and halfway between, each level by a ray from its centre and from either
  side of it; the body stops ``radius`` before the nearest surface and the rest of the move slides along it,
  at most :data:`SLIDES` times;
* **clear**: rays around the eye push it out of any surface closer than ``radius`` (corners, a wall turned
  into);
* **stand**: the vertical part of the move, then the legs: never below ``height`` above the floor (a rise of
  up to ``step`` is walked up, and a walker that stood walks down a drop of up to ``step``; a higher rise
  undoes the horizontal part), never nearer a ceiling than ``radius``. Gravity is the caller's: a downward
  move, which the floor stops; without it a walker that rose (or walked off a ledge) stays up.

Everything is float64 scene units; rays go to Embree as float32 (``RAY_DTYPE``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera.camera import RAY_DTYPE
from .kernels.embree import Tracer

UP = np.array([0.0, 1.0, 0.0])
SLIDES = 3  # a move meets at most this many surfaces in turn (a corner: two)
CLEAR_DIRECTIONS = 12  # horizontal rays around the eye that push it out of surfaces (a wall between two: 0.97 r)
STEP_OF_HEIGHT = 0.28  # the highest rise walked up, as a fraction of the eye's height (1.7 m: 0.48 m)
RADIUS_OF_HEIGHT = 0.15  # the body's radius, as a fraction of the eye's height (1.7 m: 0.26 m)
RADIUS_OF_SCENE = (1e-4, 0.02)  # ... within these fractions of the scene's diagonal (a ground plane may be vast)
FREE_RADIUS_OF_SCENE = 0.002  # the radius of a body with no floor beneath, as a fraction of the diagonal
SKIN = 1e-4  # of the radius: what a body keeps back besides, so that rounding never puts it inside a surface


@dataclass(frozen=True)
class Body:
    """radius : scene units, no surface comes nearer the eye;  height : the eye above the floor it stands on
    (None: nothing beneath, the body flies with its radius only);  step : the highest rise walked up."""

    radius: float
    height: float | None
    step: float


def cast(tracer: Tracer, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the nearest surface along each ray (inf: none) and its unit normal, facing the ray.

    origins, directions : (n, 3) float64, directions unit length.  Returns t : (n,) float64, normals : (n, 3).
    """
    hits = tracer.intersect(origins.astype(RAY_DTYPE), directions.astype(RAY_DTYPE))
    hit = hits.face >= 0
    t = np.where(hit, hits.t.astype(np.float64), np.inf)
    corners = tracer.triangles[np.maximum(hits.face, 0)].astype(np.float64)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    facing = np.einsum("ij,ij->i", normals, directions) > 0
    normals[facing] *= -1
    return t, normals


def floor_below(tracer: Tracer, eye: np.ndarray) -> float:
    """How far below ``eye`` the nearest surface is (inf: nothing)."""
    t, _ = cast(tracer, eye[None], -UP[None])
    return float(t[0])


def body_at(tracer: Tracer, eye, diagonal: float, height: float | None = None) -> Body:
    """The body of a walker whose eye is at ``eye``: its ``height`` as given, else measured (the floor beneath
    the eye; None when there is none); the radius scaled to that height, within bounds set by the scene's
    ``diagonal`` (scene units)."""
    if height is None:
        below = floor_below(tracer, np.asarray(eye, np.float64))
        height = below if np.isfinite(below) and below > 0 else None
    low, high = (fraction * diagonal for fraction in RADIUS_OF_SCENE)
    if height is None:
        return Body(radius=FREE_RADIUS_OF_SCENE * diagonal, height=None, step=0.0)
    radius = float(np.clip(RADIUS_OF_HEIGHT * height, low, high))
    return Body(radius=radius, height=float(height), step=STEP_OF_HEIGHT * height)


def _side(direction: np.ndarray) -> np.ndarray:
    """A unit vector across ``direction``: to the right of it when walking, else any."""
    across = np.cross(direction, UP)
    if np.linalg.norm(across) < 1e-6:
        across = np.cross(direction, [1.0, 0.0, 0.0])
    return across / np.linalg.norm(across)


def _levels(body: Body) -> np.ndarray:
    """Offsets from the eye of the levels a horizontal sweep looks from: the eye, then down to the knee."""
    if body.height is None:
        return np.zeros((1, 3))
    knee = body.height - body.step
    return -UP[None] * np.array([0.0, knee / 2, knee])[:, None]


def _slide(tracer: Tracer, eye: np.ndarray, move: np.ndarray, body: Body) -> np.ndarray:
    """The eye after sweeping ``move`` and sliding along what it meets."""
    levels = _levels(body)
    for _ in range(SLIDES):
        length = float(np.linalg.norm(move))
        if length < 1e-12:
            break
        direction = move / length
        side = _side(direction) * body.radius
        starts = (eye + levels)[:, None, :] + np.stack([np.zeros(3), side, -side])[None]
        # the eye is a sphere; the legs below it only need to find what the move walks into
        reach = np.repeat(np.where(np.arange(len(levels)) == 0, 1.0, 0.5) * body.radius, 3)
        t, normals = cast(tracer, starts.reshape(-1, 3), np.broadcast_to(direction, (starts.size // 3, 3)).copy())
        free = (t - reach.reshape(-1)) - SKIN * body.radius
        nearest = int(np.argmin(free))
        if free[nearest] >= length:
            return eye + move
        travel = max(0.0, float(free[nearest]))
        eye = eye + direction * travel
        normal = normals[nearest]
        if body.height is not None:  # a walker slides along walls, not up or down them
            normal = normal - UP * normal[1]
            if np.linalg.norm(normal) < 1e-6:
                break
            normal = normal / np.linalg.norm(normal)
        rest = direction * (length - travel)
        move = rest - normal * min(0.0, float(rest @ normal))
    return eye


def _clear(tracer: Tracer, eye: np.ndarray, body: Body) -> np.ndarray:
    """The eye pushed out of any surface nearer than the radius (horizontally; for a flyer, up and down too)."""
    angles = np.arange(CLEAR_DIRECTIONS) * (2 * np.pi / CLEAR_DIRECTIONS)
    directions = np.stack([np.cos(angles), np.zeros_like(angles), np.sin(angles)], axis=1)
    if body.height is None:
        directions = np.concatenate([directions, [UP, -UP]])
    for _ in range(2):
        t, _ = cast(tracer, np.broadcast_to(eye, directions.shape).copy(), directions)
        inside = np.maximum(0.0, body.radius * (1 + SKIN) - t)
        if not inside.any():
            break
        eye = eye - (inside[:, None] * directions).sum(axis=0)
    return eye


def _stand(tracer: Tracer, before: np.ndarray, eye: np.ndarray, rise: float, body: Body) -> np.ndarray:
    """The eye after the vertical move ``rise`` and the legs' rule (``before``: where the move started)."""
    up, down = cast(tracer, np.stack([eye, eye]), np.stack([UP, -UP]))[0]
    ceiling = eye[1] + max(0.0, up - body.radius * (1 + SKIN))
    if body.height is None:
        floor = eye[1] - max(0.0, down - body.radius * (1 + SKIN))
        return np.array([eye[0], min(ceiling, max(floor, eye[1] + rise)), eye[2]])
    if down < body.height - body.step and eye[:3:2].tolist() != before[:3:2].tolist():
        # walked onto something higher than a step (a railing, a table): stay where the move began
        return _stand(tracer, before, np.array([before[0], eye[1], before[2]]), rise, body)
    lowest = eye[1] - down + body.height  # the legs stand on the floor beneath
    height = max(lowest, eye[1] + rise)
    walked = eye[:3:2].tolist() != before[:3:2].tolist()
    if walked and rise <= 0 and 0 < height - lowest <= body.step and standing(tracer, before, body):
        height = lowest  # walking down a step: a walker that stood keeps standing
    return np.array([eye[0], min(ceiling, height), eye[2]])


def standing(tracer: Tracer, eye: np.ndarray, body: Body) -> bool:
    """Whether the legs of a body at ``eye`` stand on a floor (to a thousandth of their height)."""
    return body.height is not None and abs(floor_below(tracer, eye) - body.height) <= 1e-3 * body.height


def collide(tracer: Tracer | None, eye, move, body: Body) -> np.ndarray:
    """Where the eye at ``eye`` ends when it moves by ``move`` (scene units, world axes), keeping ``body``'s
    distance from surfaces, sliding along them and climbing steps: (3,) float64. A scene with no surfaces
    lets every move through."""
    eye, move = np.asarray(eye, np.float64), np.asarray(move, np.float64)
    if tracer is None:
        return eye + move
    walks = body.height is not None
    ahead = move - UP * move[1] if walks else move
    moved = _clear(tracer, _slide(tracer, eye, ahead, body), body)
    if not walks:
        return moved
    return _stand(tracer, eye, moved, float(move[1]), body)
