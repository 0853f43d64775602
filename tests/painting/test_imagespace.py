"""The image-space lookup in numpy: projection of displaced targets and edge modes (the compiled pass against it
is in ``tests/engine/test_lookup.py``)."""

import numpy as np
import pytest
from helpers.scenes import CAMERA

from rcp_server.camera.camera import Camera, Region
from rcp_server.painting.imagespace import bilinear, edge_index, lookup_coords
from rcp_server.settings.params import EDGES


def test_edge_index_maps_off_screen_indices_as_documented():
    k = np.arange(-5, 10)  # a row of n = 4 pixels: 0 1 2 3
    assert edge_index(k, 4, "clamp").tolist() == [0, 0, 0, 0, 0, 0, 1, 2, 3, 3, 3, 3, 3, 3, 3]
    assert edge_index(k, 4, "wrap").tolist() == [3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1]
    assert edge_index(k, 4, "mirror").tolist() == [3, 3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0, 0, 1]
    with pytest.raises(ValueError, match="clamp, wrap, mirror"):
        edge_index(k, 4, "repeat")


def test_bilinear_on_a_gradient_gives_the_expected_pixels_at_the_edges():
    w, h = 5, 3
    image = np.arange(w, dtype=np.float32)[None, :].repeat(h, 0) * 10.0  # columns 0 10 20 30 40
    y = np.full(7, 1.0)
    x = np.array([0.0, 2.0, 4.0, -1.0, -2.0, 4.5, 5.0])
    assert bilinear(image, x, y, "clamp").tolist() == [0, 20, 40, 0, 0, 40, 40]  # bars: the edge repeats
    assert bilinear(image, x, y, "wrap").tolist() == [0, 20, 40, 40, 30, 20, 0]  # the seam: 40 blends into 0
    assert bilinear(image, x, y, "mirror").tolist() == [0, 20, 40, 0, 10, 40, 40]  # runs back from the edge
    # between centres it is linear; along y the same rules hold
    assert bilinear(image, np.array([1.25]), np.array([1.0]), "clamp").tolist() == [12.5]
    column = image.T.copy()  # rows 0 10 20 30 40
    assert bilinear(column, np.array([1.0, 1.0]), np.array([-2.0, 5.5]), "mirror").tolist() == [10.0, 35.0]
    # a huge or far coordinate stays inside the image and finite
    far = np.array([1e300, -1e300, 7e15])
    for edge in EDGES:
        value = bilinear(image, far, np.ones(3), edge)
        assert np.all((value >= 0) & (value <= 40))


def test_lookup_coords_of_no_displacement_are_the_pixels_own_centres_exactly():
    camera = Camera((1.0, 2.0, 3.0), (-2.0, 0.5, -1.0), fov=47.0)
    region = Region(17, 11, 2, 3, 9, 6)
    x, y, ok = lookup_coords(np.zeros((region.pixel_count, 3)), camera, region)
    i, j = region.pixel_coords()
    assert ok.all() and np.array_equal(x, i) and np.array_equal(y, j)


def test_lookup_coords_move_lambda_pixels_along_r_and_u_and_refuse_points_behind_the_eye():
    region = Region(40, 30)
    p = CAMERA.pixel_pitch(30)
    r, u, f = CAMERA.basis()
    n = region.pixel_count
    i, j = region.pixel_coords()
    x, y, ok = lookup_coords(np.broadcast_to(3.0 * p * r - 2.0 * p * u, (n, 3)), CAMERA, region)
    assert ok.all()
    np.testing.assert_allclose(x - i, 3.0, atol=1e-9)
    np.testing.assert_allclose(y - j, 2.0, atol=1e-9)  # up on screen is a smaller row
    # along f only: the target moves away, so its projection moves towards the image centre
    x, y, ok = lookup_coords(np.broadcast_to(0.7 * f, (n, 3)), CAMERA, region)
    np.testing.assert_allclose(x + 0.5 - 20.0, (i + 0.5 - 20.0) / 1.7, atol=1e-9)
    np.testing.assert_allclose(y + 0.5 - 15.0, (j + 0.5 - 15.0) / 1.7, atol=1e-9)
    # at or behind the eye, or not finite: no projection, the pixel keeps its own place
    v = np.zeros((n, 3))
    v[0] = -1.0 * f
    v[1] = -3.0 * f + r
    v[2] = (np.nan, 0.0, 0.0)
    v[3] = (np.inf, 0.0, 0.0)
    x, y, ok = lookup_coords(v, CAMERA, region)
    assert ok.tolist()[:5] == [False, False, False, False, True]
    assert np.array_equal(x[:4], i[:4]) and np.array_equal(y[:4], j[:4])
