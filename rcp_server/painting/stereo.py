"""Where the two eyes of a stereo painting see the same thing, and the mode in which they share their smudges.

Each eye is painted from its own previous image (the paper's VR version), so the two smudges of one surface
point may differ: in a headset the eyes then see two paintings (rivalry; ``rcp bench projection`` measures how
often). With the painting setting ``eyes = "shared"`` the right eye reads its displacement fields from the left
eye's previous image, at the pixel that sees the same surface point in the plain render (:func:`partners`):
both eyes smudge a point alike. Where the left eye does not see the right eye's point, the right eye reads its
own. The sky is the same direction from both eyes (it is infinitely far), so it pairs pixel with pixel.
"""

from __future__ import annotations

import numpy as np

from ..camera.camera import Camera, Region, directions_at, eye_pixels, pixel_frames, project
from ..engine import kernels
from ..scene.scene import Scene
from .seen import visible_faces

SAME_POINT = 0.01
"""Two eyes' hits count as one surface point within this share of its distance, or within 1.5 pixels' width
there (the other eye's nearest pixel centre may sit half a pixel off the point)."""


def points(camera: Camera, region: Region, seen: kernels.Seen) -> tuple[np.ndarray, np.ndarray]:
    """The point each pixel centre of the painting ``region`` sees, (n, 3) float64 (NaN on the sky), and each
    pixel's eye (n, 3), from the plain render's hits ``seen`` (a bundles.Seen of the whole painting)."""
    i, j = region.pixel_coords()
    eyes, *_ = pixel_frames(camera, region, i, j)
    _, ei, ej = eye_pixels(camera, region, i, j)
    d, *_ = directions_at(camera, region, ei + 0.5, ej + 0.5)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hit = seen.face >= 0
    distance = np.full(len(hit), np.nan)
    distance[hit] = seen.distance[hit]  # a miss's distance is whatever the buffer held: not read
    return eyes + distance[:, None] * d, eyes


def partners(camera: Camera, region: Region, seen: kernels.Seen) -> np.ndarray:
    """For each pixel of a stereo painting, the pixel of the other eye that sees the same surface point (the
    same pixel of the other eye's image on the sky), or -1: (n,) int64."""
    found = np.full(region.pixel_count, -1, np.int64)
    if camera.stereo == "mono":
        return found
    i, j = region.pixel_coords()
    side, ei, ej = eye_pixels(camera, region, i, j)
    world, eyes = points(camera, region, seen)
    width, height = camera.eye_size(region.full_width, region.full_height)
    across = np.where(side < 0, 1, -1)  # the other eye
    # the sky: the same pixel of the other eye's image
    x_other = ei + np.where((across > 0) & (camera.stereo == "side-by-side"), width, 0)
    y_other = ej + np.where((across > 0) & (camera.stereo == "top-bottom"), height, 0)
    sky = np.isnan(world[:, 0])
    found[sky] = (y_other * region.full_width + x_other)[sky]
    # a surface: seen from the other eye (on the sphere each column has its own eye: once more from the eye of the
    # pixel found), the nearest pixel, if that pixel sees the same point
    hit = np.flatnonzero(~sky)
    other_eye = eyes[hit] - 2.0 * (eyes[hit] - np.asarray(camera.eye))  # the mirror eye: a first guess
    target = np.zeros(len(hit), np.int64)
    ok = np.zeros(len(hit), bool)
    for _ in range(2):
        x, y, ok = project(camera, region, across[hit], world[hit] - other_eye)
        x = np.clip(np.rint(x), 0, region.full_width - 1).astype(np.int64)
        y = np.clip(np.rint(y), 0, region.full_height - 1).astype(np.int64)
        target = y * region.full_width + x
        other_eye = eyes[target]
    gap = np.linalg.norm(world[target] - world[hit], axis=1)
    reach = np.linalg.norm(world[hit] - other_eye, axis=1)
    near = reach * max(SAME_POINT, 1.5 * camera.pixel_pitch(height))
    same = ok & (side[target] == across[hit]) & (gap < near)  # NaN (the other eye saw the sky): False
    found[hit[same]] = target[same]
    return found


def shared_sources(scene: Scene, time: float, camera: Camera, region: Region) -> np.ndarray:
    """Which pixel of the painting each pixel reads its displacement from when the eyes share their smudges:
    a right-eye pixel its left partner (:func:`partners`), every other pixel itself."""
    seen = kernels.Seen.empty(region.full_width, region.full_height)
    visible_faces(scene, time, camera, region, seen)
    source = np.arange(region.pixel_count)
    pair = partners(camera, region, seen)
    side, _, _ = eye_pixels(camera, region, *region.pixel_coords())
    reads_left = (side > 0) & (pair >= 0)
    source[reads_left] = pair[reads_left]
    return source
