"""Outlines, a shading result: ink where the object, the surface normal or the depth jumps between
neighbouring pixels of the frame camera's plain view (the paper's "nonphotorealistic shaders").

What the pixel centres see is traced once a painting (:func:`ink`, the one caller of :func:`edges`); a
pixel gets ink where it and a neighbour (right or below) show different objects, normals more than
``CREASE_DEGREES`` apart, or depths more than ``DEPTH_JUMP`` apart (relative). Shading then inks a hit of a
material with an outline when it lies on the surface its pixel of that view saw (``kernels.shade``): every
iteration shades its displaced rays so, and the painting smudges the lines like any other paint.
"""

from __future__ import annotations

import math

import numpy as np

from ..camera.camera import Camera, Region, directions_at, eye_pixels, pixel_frames
from ..engine import kernels
from ..scene.scene import Geometry
from .seen import visible_faces

CREASE_DEGREES = 40.0  # a fold sharper than this is drawn (a smooth sphere's facets are not)
DEPTH_JUMP = 0.1  # a step in depth of more than a tenth is drawn (a floor seen at a grazing angle is not)

NO_INK = kernels.Ink(False, np.zeros(1, np.uint8), np.zeros(1, np.float32))


def edges(face: np.ndarray, distance: np.ndarray, camera: Camera, geometry: Geometry, region: Region):
    """Ink (n,) float32 (1 on an edge, else 0) and each pixel's distance to what it sees (n,) float32 (0 on
    the sky) of ``region`` (full-width rows of a painting, n pixels), from what its pixel centres see: ``face``
    (n,) int32 (-1 the sky) and ``distance`` along each unit primary ray. Neighbours in two eyes' images are
    not compared."""
    width, height = region.width, region.height
    i, j = region.pixel_coords()
    side, ei, ej = eye_pixels(camera, region, i, j)
    directions, *_ = directions_at(camera, region, ei + 0.5, ej + 0.5)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    *_, forward = pixel_frames(camera, region, i, j)
    hit = face >= 0
    depth = np.where(hit, distance * (directions * forward).sum(axis=1), np.inf).reshape(height, width)
    eye = side.reshape(height, width)
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
        jump &= eye[a] == eye[b]
        ink[a] |= jump
        ink[b] |= jump
    return ink.astype(np.uint8).ravel(), np.where(hit, distance, 0.0).astype(np.float32)


INK_BAND = 1 << 14  # pixels of the ink's pass at a time: its float64 work costs some 300 bytes a pixel


def ink(scene, time: float, camera: Camera, width: int, height: int) -> kernels.Ink:
    """The ink of a painting of ``scene`` at ``time`` seen by ``camera`` at ``width x height``; none (no pass
    at all) unless some material draws outlines."""
    geometry, tracer = scene.geometry(time)
    if tracer is None or not (geometry.material_outline > 0).any():
        return NO_INK
    grid, far = np.zeros(width * height, np.uint8), np.zeros(width * height, np.float32)
    band = max(1, INK_BAND // width)
    for y0 in range(0, height, band):
        # a band and the first row of the next: an edge between the two inks both sides
        rows = Region(width, height, 0, y0, width, min(band + 1, height - y0))
        seen = kernels.Seen.empty(rows.width, rows.height)
        visible_faces(scene, time, camera, rows, seen)
        ink, distance = edges(seen.face, seen.distance, camera, geometry, rows)
        at = slice(y0 * width, (y0 + rows.height) * width)
        np.maximum(grid[at], ink, out=grid[at])
        far[at] = distance
    return kernels.Ink(True, grid, far)
