"""The second kind of randomness: noise that belongs to the surface point, not to the screen pixel."""

from dataclasses import replace

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W

from rcp_server.camera.camera import Region
from rcp_server.painting.assign import displacements, setup_tile
from rcp_server.painting.fields import surface_noise
from rcp_server.painting.loop import paint
from rcp_server.settings.params import PaintParams

SHIFT = 5  # pixels between the two cameras' views of the plane


def test_the_noise_is_a_seeded_function_of_the_point_alone():
    rng = np.random.default_rng(0)
    points = rng.uniform(-50, 50, (500, 3))
    h, v = surface_noise(3, points, 0.7)
    h_alone, v_alone = surface_noise(3, points[17:18], 0.7)  # whatever else is drawn beside it
    assert h[17] == h_alone[0] and np.array_equal(v[17], v_alone[0])
    assert np.all(np.abs(h) <= 1) and np.all(np.abs(v) <= 1) and h.std() > 0.4
    assert not np.array_equal(h, surface_noise(4, points, 0.7)[0])  # another seed, another pattern
    # one value per cell: points a hair apart agree, almost always
    near = surface_noise(3, points + 1e-6, 0.7)[0]
    assert (near == h).mean() > 0.99
    nowhere = surface_noise(3, np.full((2, 3), np.nan), 0.7)  # the sky has no point: no noise
    assert not nowhere[0].any() and not nowhere[1].any()


def test_hatch_noise_is_constant_along_the_smudge_and_varies_across():
    rng = np.random.default_rng(1)
    points = rng.uniform(-5, 5, (400, 3))
    across = np.tile([0.0, 0.0, 1.0], (400, 1))  # the smudge runs in the x-y plane
    h, _ = surface_noise(0, points, 0.25, across)
    along = points + rng.uniform(-3, 3, (400, 3)) * [1.0, 1.0, 0.0]
    np.testing.assert_array_equal(surface_noise(0, along, 0.25, across)[0], h)
    assert len(np.unique(h)) > 20  # lines at different offsets across differ


def test_the_same_world_point_gets_the_same_noise_from_two_cameras(gradient_scene):
    """Two cameras SHIFT pixels apart at the plane's depth see the same points at pixels SHIFT apart: the surface
    noise's displacement agrees there; the screen noise's does not (it belongs to the pixel)."""
    pitch = CAMERA.pixel_pitch(H)
    other = CAMERA.moved(eye=(SHIFT * pitch * 4.0, 0.0, 0.0), look_at=(SHIFT * pitch * 4.0, 0.0, -1.0))
    region = Region(W, H)
    surface = PaintParams(iterations=1, lambda_p=6.0, surface_noise=1.0, surface_scale=0.5, grain=0.3)
    screen = replace(surface, surface_noise=0.0, surface_scale=0.0, noise=1.0)

    def fields(camera, params):
        state = paint(gradient_scene, camera, W, H, replace(surface, noise=params.noise)).state
        v_p, _ = displacements(state, setup_tile(camera, region, params), params, 4.0, anchor=state.position)
        return v_p.reshape(H, W, 3), state.position.reshape(H, W, 3)

    (a, pa), (b, pb) = fields(CAMERA, surface), fields(other, surface)
    np.testing.assert_allclose(pa[:, SHIFT:], pb[:, :-SHIFT], atol=1e-5)  # the same points, SHIFT pixels apart
    same = np.isclose(a[:, SHIFT:], b[:, :-SHIFT], rtol=0, atol=1e-6).all(axis=2)
    assert same.mean() > 0.99  # (a point within a hair of a cell's wall may fall either side)
    assert not np.allclose(a, fields(CAMERA, replace(surface, surface_noise=0.0, surface_scale=0.0))[0])
    (c, _), (d, _) = fields(CAMERA, screen), fields(other, screen)
    assert np.isclose(c[:, SHIFT:], d[:, :-SHIFT], rtol=0, atol=1e-6).all(axis=2).mean() < 0.2


@pytest.mark.parametrize("hatch", [False, True])
def test_traced_and_image_paint_surface_noise(busy_scene, hatch):
    params = PaintParams(mapping="normal", lambda_p=14.0, surface_noise=0.6, surface_scale=0.8, hatch=hatch, grain=0.4)
    exact = paint(busy_scene, CAMERA, W, H, params).image
    plain = paint(busy_scene, CAMERA, W, H, replace(params, iterations=1)).image
    without = paint(busy_scene, CAMERA, W, H, replace(params, surface_noise=0.0, surface_scale=0.0)).image
    assert (np.abs(exact - without).max(axis=2) > 2 / 255).mean() > 0.05  # the noise shows
    image = paint(busy_scene, CAMERA, W, H, replace(params, method="image")).image
    assert np.isfinite(image).all() and (np.abs(image - plain).max(axis=2) > 2 / 255).mean() > 0.05
