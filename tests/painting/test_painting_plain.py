"""The plain render: iteration 1, and every iteration when nothing moves (lambda 0)."""

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, make_scene

from rcp_server.camera.camera import Region
from rcp_server.painting.assign import displacements, setup_tile
from rcp_server.painting.loop import paint
from rcp_server.settings.mappings import BUILT_IN
from rcp_server.settings.params import PaintParams


@pytest.mark.parametrize("mapping", BUILT_IN + ("test-probe",))
def test_iteration_one_is_the_plain_render_for_every_mapping(busy_scene, mapping):
    plain = paint(busy_scene, CAMERA, W, H, PaintParams(iterations=1)).image
    result = paint(
        busy_scene,
        CAMERA,
        W,
        H,
        PaintParams(mapping=mapping, iterations=3, lambda_p=6.0, lambda_e=0.2, noise=0.3),
        keep_iterations=True,
    )
    np.testing.assert_array_equal(result.iterations[0], plain)
    alone = paint(busy_scene, CAMERA, W, H, PaintParams(mapping=mapping, iterations=1, lambda_p=6.0, lambda_e=0.2))
    np.testing.assert_array_equal(alone.image, plain)
    # and the painting does move afterwards, so the equality above is not vacuous
    assert not np.array_equal(result.iterations[2], plain)
    np.testing.assert_array_equal(result.iterations[2], result.image)


@pytest.mark.parametrize("spp", [1, 4])
@pytest.mark.parametrize("mapping", BUILT_IN)
def test_zero_lambdas_give_the_plain_render_at_every_iteration(busy_scene, mapping, spp):
    plain = paint(busy_scene, CAMERA, W, H, PaintParams(iterations=1, spp=spp, seed=3)).image
    result = paint(
        busy_scene,
        CAMERA,
        W,
        H,
        PaintParams(
            mapping=mapping,
            eye_mapping="depth",
            iterations=4,
            spp=spp,
            seed=3,
            lambda_p=0.0,
            lambda_e=0.0,
            noise=0.8,
        ),
        keep_iterations=True,
    )
    assert len(result.iterations) == 4
    for image in result.iterations:
        np.testing.assert_array_equal(image, plain)


def test_uniform_grey_world_never_moves_a_ray():
    grey = make_scene([], sky=(0.5, 0.5, 0.5))
    params = PaintParams(mapping="depth", eye_mapping="color", lambda_p=30.0, lambda_e=2.0, iterations=4)
    result = paint(grey, CAMERA, W, H, params, keep_iterations=True)
    for image in result.iterations:
        assert np.all(image == np.float32(0.5))
    region = Region(W, H)
    v_p, v_e = displacements(result.state, setup_tile(CAMERA, region, params), params, 1.0)
    assert np.all(v_p == 0.0) and np.all(v_e == 0.0)
    # the rays themselves: every recorded direction is the plain primary ray's
    probe = PaintParams(mapping="color", eye_mapping="test-probe", lambda_p=30.0, lambda_e=1.0, iterations=4)
    state = paint(grey, CAMERA, W, H, probe).state
    i, j = region.pixel_coords()
    plane = setup_tile(CAMERA, region, probe).targets()
    primary = plane - np.asarray(CAMERA.eye)
    primary /= np.linalg.norm(primary, axis=1, keepdims=True)
    np.testing.assert_allclose(state.direction, primary, rtol=0, atol=1e-7)
