"""Where a model is seen from, and lit from, when nobody said: its file's own cameras and lights first; else
from inside when it is an interior, from where it faces when it is a figure.

Pure functions of the traced geometry (``scene.Geometry`` and its ``tracer.Tracer``): a few hundred rays
decide, so framing costs nothing beside building the tree that painting needs anyway.

* **Interior**: the model encloses a point (its bounding box's centre, or the eye point below it) when most
  rays from there hit it, and hit the sides of its surfaces that face that point (from inside a closed
  figure, rays meet the backs of its faces instead). The camera then stands at that point, at a third of
  the room's height, looking along the room's longest horizontal extent, towards the farther wall.
* **Figure**: seen from the front (glTF's +z), a little above and to the right; unless it faces -z: its
  top (a head) reaches towards -z while its bottom (hind legs, a tail) trails towards +z
  (:func:`facing_sign`), in which case it is seen from there.
"""

from __future__ import annotations

import math

import numpy as np

from ..camera.camera import RAY_DTYPE, Camera
from ..engine.kernels.embree import Tracer
from .gltf import PunctualLight, Viewpoint, triple
from .scene import Geometry, Light

EYE_HEIGHT = 1 / 3  # of the room's height, above its floor
INTERIOR_FOV = 70.0
FIGURE_FOV = 45.0
ENCLOSED = 0.5  # of the rays from a point that must hit the model, on the faces that look at the point
LEAN = 0.05  # of its depth, that a figure's top leans forward and its bottom back (facing_sign)
PROBE_RAYS = 512
DEFAULT_LIGHT = (-0.4, -1.0, -0.5)
DEFAULT_AMBIENT = 0.35


def sphere_directions(count: int) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere (a Fibonacci lattice): (count, 3) float32."""
    k = np.arange(count) + 0.5
    y = 1.0 - 2.0 * k / count
    ring = np.sqrt(1.0 - y * y)
    angle = math.pi * (3.0 - math.sqrt(5.0)) * k
    return np.stack([ring * np.cos(angle), y, ring * np.sin(angle)], axis=1).astype(RAY_DTYPE)


def enclosure(geometry: Geometry, tracer: Tracer, point) -> float:
    """Of rays from ``point`` in every direction, the fraction that hit the model on a face turned towards
    ``point`` (the inside of a room; a closed figure's inside shows the backs of its faces)."""
    directions = sphere_directions(PROBE_RAYS)
    origins = np.broadcast_to(np.asarray(point, RAY_DTYPE), directions.shape).copy()
    hits = tracer.intersect(origins, directions)
    hit = hits.face >= 0
    tri = geometry.triangles[hits.face[hit]].astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    facing = np.einsum("nk,nk->n", normal, directions[hit]) < 0
    return float(facing.sum()) / len(directions)


def interior_camera(geometry: Geometry, tracer: Tracer) -> Camera | None:
    """A camera inside the model at a third of its height, looking along its longest horizontal extent,
    when the model encloses its centre or that eye point; None otherwise."""
    lo, hi = geometry.bounds
    center = (lo + hi) / 2
    eye = np.array([center[0], lo[1] + EYE_HEIGHT * (hi[1] - lo[1]), center[2]])
    if max(enclosure(geometry, tracer, center), enclosure(geometry, tracer, eye)) <= ENCLOSED:
        return None
    axis = np.zeros(3)
    axis[0 if hi[0] - lo[0] >= hi[2] - lo[2] else 2] = 1.0
    # towards the farther wall along that axis: the longer free view
    origins = np.array([eye, eye], RAY_DTYPE)
    hits = tracer.intersect(origins, np.array([axis, -axis], RAY_DTYPE))
    reach = np.where(hits.face >= 0, hits.t, np.float32(np.linalg.norm(hi - lo)))
    forward = axis if reach[0] >= reach[1] else -axis
    return Camera(tuple(eye), tuple(eye + forward * max(float(reach.max()) * 0.5, 1e-3)), fov=INTERIOR_FOV)


def facing_sign(geometry: Geometry) -> float:
    """+1 when the model faces +z (glTF's front) or shows no way it faces, -1 when it faces -z: its top
    quarter (a head) lies towards -z of the whole and its bottom quarter (hind legs, a tail) towards +z,
    each by more than LEAN of its depth (surface-weighted centroids). Measured on the shared models: the
    armadillo -0.11 and +0.10, Spot -0.25 and +0.13 (both face -z); the bunny -0.19 and +0.02 (it faces
    sideways), the duck and the teapot within 0.01."""
    tri = geometry.triangles.astype(np.float64)
    centre = tri.mean(axis=1)
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    lo, hi = geometry.bounds
    height, depth = float(hi[1] - lo[1]), float(hi[2] - lo[2])
    if not (height > 0 and depth > 0 and area.sum() > 0):
        return 1.0
    mean_z = float(np.dot(centre[:, 2], area) / area.sum())

    def lean(band: np.ndarray) -> float:
        weight = area[band].sum()
        return float(np.dot(centre[band, 2], area[band]) / weight - mean_z) / depth if weight > 0 else 0.0

    top = lean(centre[:, 1] > hi[1] - 0.25 * height)
    bottom = lean(centre[:, 1] < lo[1] + 0.25 * height)
    return -1.0 if top < -LEAN and bottom > LEAN else 1.0


def figure_camera(geometry: Geometry, fov: float = FIGURE_FOV) -> Camera:
    """The model seen from its front, a little above and to the right: glTF's +z, or -z when it faces
    there (:func:`facing_sign`)."""
    lo, hi = geometry.bounds
    center, radius = (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    distance = radius / math.sin(math.radians(fov) / 2) * 1.05
    view = np.array([0.45, 0.35, 1.0]) / np.linalg.norm([0.45, 0.35, 1.0])
    if facing_sign(geometry) < 0:
        view = view * [-1.0, 1.0, -1.0]  # still above and to its right, as it sees it
    return Camera(tuple(center + distance * view), tuple(center), fov=fov)


def default_camera(geometry: Geometry, tracer: Tracer | None) -> Camera:
    """The camera of a model that brings none: from inside an interior, else from where it faces."""
    if tracer is not None:
        inside = interior_camera(geometry, tracer)
        if inside is not None:
            return inside
    return figure_camera(geometry)


def viewpoint_camera(viewpoint: Viewpoint, geometry: Geometry, tracer: Tracer | None, world_from_model=None) -> Camera:
    """A file's camera as a Camera: its look_at where its view first meets the model (so the depth
    mapping focuses there), else at the distance of the model's centre. ``world_from_model``: 4x4 placing
    the file in a scene (default the identity)."""
    m = np.eye(4) if world_from_model is None else np.asarray(world_from_model, np.float64)
    eye = m[:3, :3] @ viewpoint.eye + m[:3, 3]
    forward = m[:3, :3] @ viewpoint.forward
    forward /= np.linalg.norm(forward)
    up = m[:3, :3] @ viewpoint.up
    lo, hi = geometry.bounds
    reach = max(float(np.dot((lo + hi) / 2 - eye, forward)), 1e-3 * float(np.linalg.norm(hi - lo)), 1e-3)
    if tracer is not None:
        hit = tracer.intersect(eye[None].astype(RAY_DTYPE), forward[None].astype(RAY_DTYPE))
        if hit.face[0] >= 0:
            reach = float(hit.t[0])
    return Camera(tuple(eye), tuple(eye + reach * forward), tuple(up), fov=float(viewpoint.fov))


def default_light(geometry: Geometry) -> Light:
    """A soft light from the front, above and to the left, for a model that brings none: from where the
    figure faces (:func:`facing_sign`), as its camera stands there."""
    direction = np.asarray(DEFAULT_LIGHT, np.float64) / np.linalg.norm(DEFAULT_LIGHT)
    if geometry.face_count and facing_sign(geometry) < 0:
        direction = direction * [-1.0, 1.0, -1.0]
    return Light(triple(direction), DEFAULT_AMBIENT)


def light_of(lights: list[PunctualLight], geometry: Geometry, world_from_model=None) -> Light:
    """The scene's one directional light from a file's lights: its first directional light; else its first
    spot light's axis; else the way from its first point light to the model's centre; else a soft light
    from the front. Color and intensity are not modelled: one white light plus ambient."""
    m = np.eye(4) if world_from_model is None else np.asarray(world_from_model, np.float64)
    by_kind = {kind: [light for light in lights if light.kind == kind] for kind in ("directional", "spot", "point")}
    direction = np.asarray(DEFAULT_LIGHT, np.float64)
    if by_kind["directional"] or by_kind["spot"]:
        direction = m[:3, :3] @ (by_kind["directional"] or by_kind["spot"])[0].direction
    elif by_kind["point"]:
        lo, hi = geometry.bounds
        position = m[:3, :3] @ by_kind["point"][0].position + m[:3, 3]
        direction = (lo + hi) / 2 - position
    length = float(np.linalg.norm(direction))
    if not length > 1e-12:
        direction, length = np.asarray(DEFAULT_LIGHT, np.float64), float(np.linalg.norm(DEFAULT_LIGHT))
    return Light(triple(direction / length), DEFAULT_AMBIENT)
