"""The compiled projections (``engine/kernels/projection.py``) against their numpy twins in ``camera.py``, on a
camera of every projection: which eye a pixel belongs to, its local frame, where its targets lie and where a
direction lands back in the image."""

import numba
import numpy as np
import pytest
from helpers.cameras import CAMERAS, EYE, painting_size

from rcp_server.camera.camera import Region, directions_at, eye_pixels, pixel_frames, project
from rcp_server.engine import kernels
from rcp_server.engine.kernels.projection import centre_frame, locate, target_offset, to_pixel


@numba.njit
def _kernel_map(plane, i, j, xs, ys, d):
    """Per pixel (i, j) of the painting: locate, centre_frame, target_offset at (xs, ys), to_pixel of d."""
    n = len(i)
    side = np.empty(n, np.int64)
    frame = np.empty((n, 9))
    offset = np.empty((n, 3))
    back = np.empty((n, 3))
    for k in range(n):
        s, li, lj = locate(plane, i[k], j[k])
        side[k] = s
        f = centre_frame(plane, li, lj)
        for q in range(9):
            frame[k, q] = f[q]
        offset[k, 0], offset[k, 1], offset[k, 2] = target_offset(plane, li + xs[k], lj + ys[k])
        x, y, ok = to_pixel(plane, s, d[k, 0], d[k, 1], d[k, 2])
        back[k, 0], back[k, 1], back[k, 2] = x, y, 1.0 if ok else 0.0
    return side, frame, offset, back


@pytest.mark.parametrize("name", sorted(CAMERAS) + ["perspective"])
def test_the_compiled_projection_is_its_numpy_twin(name):
    camera = CAMERAS.get(name, EYE)
    region = Region(*painting_size(camera))
    i, j = region.pixel_coords()
    rng = np.random.default_rng(3)
    xs, ys = rng.uniform(0, 1, len(i)), rng.uniform(0, 1, len(i))
    d = rng.normal(size=(len(i), 3))
    side, frame, offset, back = _kernel_map(kernels.ImagePlane.of(camera, region), i, j, xs, ys, d)
    twin_side, ei, ej = eye_pixels(camera, region, i, j)
    np.testing.assert_array_equal(side, twin_side)
    eyes, r, u, f = pixel_frames(camera, region, i, j)
    np.testing.assert_allclose(frame, np.hstack([r, u, f]), atol=1e-12)
    np.testing.assert_allclose(eyes, np.asarray(camera.eye) + (0.5 * camera.ipd * side)[:, None] * r, atol=1e-12)
    twin_offset, *_ = directions_at(camera, region, ei + xs, ej + ys)
    np.testing.assert_allclose(offset, twin_offset, atol=1e-12)
    x, y, ok = project(camera, region, side, d)
    np.testing.assert_array_equal(back[:, 2] == 1.0, ok)
    np.testing.assert_allclose(back[ok, 0], x[ok], atol=1e-9)
    np.testing.assert_allclose(back[ok, 1], y[ok], atol=1e-9)
    # the inverse map takes each centre's own direction back to that centre
    centre, *_ = directions_at(camera, region, ei + 0.5, ej + 0.5)
    x, y, ok = project(camera, region, side, centre)
    assert ok.all()
    np.testing.assert_allclose(x, i, atol=1e-9)
    np.testing.assert_allclose(y, j, atol=1e-9)
