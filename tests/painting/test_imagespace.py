"""The image-space lookup: projection of displaced targets, edge modes, and the compiled pass against numpy."""

import numpy as np
import pytest
from helpers.scenes import CAMERA

from rcp_server.camera.camera import Camera, Region
from rcp_server.engine import kernels
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


def _dummy(ndim):
    return np.zeros(1, np.float32) if ndim == 1 else np.zeros((1, 3), np.float32)


@pytest.mark.parametrize("channels", [("color",), ("color", "depth"), ("color", "normal", "direction")])
@pytest.mark.parametrize("edge", EDGES)
def test_look_up_kernel_matches_numpy_reference(edge, channels):
    rng = np.random.default_rng(5)
    camera = Camera((0.5, 1.0, 2.0), (-1.0, 0.0, -3.0), (0.1, 1.0, 0.0), fov=55.0)
    w, h = 23, 13
    region = Region(w, h, 3, 4, 15, 6)
    n = region.pixel_count
    p = camera.pixel_pitch(h)
    plain = {
        "color": rng.uniform(0, 1, (w * h, 3)).astype(np.float32),
        "depth": rng.uniform(1, 9, w * h).astype(np.float32),
        "normal": rng.normal(size=(w * h, 3)).astype(np.float32),
        "direction": rng.normal(size=(w * h, 3)).astype(np.float32),
    }
    plain["direction"] /= np.linalg.norm(plain["direction"], axis=1, keepdims=True)
    v_p = rng.normal(0, 12 * p, (n, 3)) @ np.diag([1.0, 1.0, 0.02])  # lookups up to a dozen pixels off screen
    v_p[0] = -2.0 * np.stack(camera.basis())[2]  # behind the eye
    v_p[1] = (np.nan, 0.0, 0.0)
    out = {name: np.full((n, 3) if name != "depth" else n, 7.0, np.float32) for name in plain}
    plane = kernels.ImagePlane.of(camera, region)
    kernels.look_up(
        v_p=v_p,
        moves=True,
        plane=plane,
        edge=EDGES.index(edge),
        plain=kernels.Channels(
            **{name: plain[name] if name in channels else _dummy(2 - (name == "depth")) for name in plain}
        ),
        out=kernels.Channels(**out),
    )
    x, y, ok = lookup_coords(v_p, camera, region)
    assert not ok[0] and not ok[1] and ok[2:].all()
    assert (x < 0).any() and (x > w - 1).any()  # the edges are exercised
    for name in plain:
        if name not in channels:
            assert np.all(out[name] == 7.0)  # not recorded, not written
            continue
        image = plain[name].reshape(h, w, *plain[name].shape[1:])
        expected = bilinear(image, x, y, edge)
        if name == "direction":
            expected /= np.linalg.norm(expected, axis=1, keepdims=True)
        np.testing.assert_allclose(out[name], expected, rtol=1e-5, atol=1e-5)
    # no displacement: each pixel reads exactly its own plain value
    kernels.look_up(
        v_p=v_p,
        moves=False,
        plane=plane,
        edge=EDGES.index(edge),
        plain=kernels.Channels(plain["color"], _dummy(1), _dummy(2), _dummy(2)),
        out=kernels.Channels(out["color"], _dummy(1), _dummy(2), _dummy(2)),
    )
    i, j = region.pixel_coords()
    np.testing.assert_array_equal(out["color"], plain["color"][j * w + i])
