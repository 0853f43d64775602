"""Outlines, a shading result: ink where the object, the surface normal or the depth jumps between
neighbouring pixels of the frame camera's plain view (the paper's "nonphotorealistic shaders").

What the pixel centres see is traced once a painting (``raytrace.visible_faces``); a pixel gets ink where
it and a neighbour (right or below) show different objects, normals more than ``CREASE_DEGREES`` apart, or
depths more than ``DEPTH_JUMP`` apart (relative). Shading then inks a hit of a material with an outline when
it lies on the surface its pixel of that view saw (``kernels.shade``): every iteration shades its displaced
rays so, and the painting smudges the lines like any other paint.
"""

from __future__ import annotations

import math

import numpy as np

from . import kernels
from .camera import Camera, Region
from .scene import Geometry

CREASE_DEGREES = 40.0  # a fold sharper than this is drawn (a smooth sphere's facets are not)
DEPTH_JUMP = 0.1  # a step in depth of more than a tenth is drawn (a floor seen at a grazing angle is not)

NO_INK = kernels.Ink(False, np.zeros(1, np.float32), np.zeros(1, np.float32), np.eye(3), 1.0, 1.0, 1, 1)


def edges(face: np.ndarray, distance: np.ndarray, camera: Camera, geometry: Geometry, width: int, height: int):
    """Ink (H*W,) float32 (1 on an edge, else 0) and view depth (H*W,) float32 from what the pixel centres see:
    ``face`` (H*W,) int32 (-1 the sky) and ``distance`` along each unit primary ray."""
    r, u, f = camera.basis()
    i, j = Region(width, height).pixel_coords()
    tan_half = camera.half_height()
    aspect = width / height
    directions = (
        np.outer((2.0 * (i + 0.5) / width - 1.0) * aspect * tan_half, r)
        + np.outer((1.0 - 2.0 * (j + 0.5) / height) * tan_half, u)
        + f
    )
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hit = face >= 0
    depth = np.where(hit, distance * (directions @ f), np.inf).reshape(height, width)
    tri = geometry.triangles[np.maximum(face, 0)].astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    normal *= np.where(np.einsum("nk,nk->n", normal, directions) > 0, -1.0, 1.0)[:, None]  # towards the eye
    normal = normal.reshape(height, width, 3)
    obj = np.where(hit, geometry.face_object[np.maximum(face, 0)], -1).reshape(height, width)
    crease = math.cos(math.radians(CREASE_DEGREES))
    ink = np.zeros((height, width), bool)
    for a, b in (
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        ((slice(None, -1),), (slice(1, None),)),
    ):
        with np.errstate(invalid="ignore"):  # the sky's depth is infinite
            jump = (obj[a] != obj[b]) | (np.abs(depth[a] - depth[b]) > DEPTH_JUMP * np.minimum(depth[a], depth[b]))
        jump |= (obj[a] >= 0) & (obj[b] >= 0) & ((normal[a] * normal[b]).sum(axis=-1) < crease)
        ink[a] |= jump
        ink[b] |= jump
    return ink.astype(np.float32).ravel(), np.where(np.isfinite(depth), depth, 0.0).astype(np.float32).ravel()


def ink(scene, time: float, camera: Camera, width: int, height: int) -> kernels.Ink:
    """The ink of a painting of ``scene`` at ``time`` seen by ``camera`` at ``width x height``; none (no pass
    at all) unless some material draws outlines."""
    from .raytrace import visible_faces  # the camera's pass; raytrace takes the ink from here

    geometry, tracer = scene.geometry(time)
    if tracer is None or not (geometry.material_outline > 0).any():
        return NO_INK
    seen = kernels.Seen.empty(width, height)
    visible_faces(scene, time, camera, Region(width, height), seen)
    grid, depth = edges(seen.face, seen.distance, camera, geometry, width, height)
    return kernels.Ink(True, grid, depth, np.stack(camera.basis()), camera.half_height(), width / height, width, height)
