"""The image-space method as the painting runs it: the plain render at lambda 0, agreement with tracing
on screen, temporal mode, the shared pool."""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, make_scene

from rcp_server.camera.camera import Region
from rcp_server.painting.loop import Abandoned, paint
from rcp_server.settings.mappings import BUILT_IN
from rcp_server.settings.params import PaintParams


@pytest.mark.parametrize("spp", [1, 3])
@pytest.mark.parametrize("mapping", BUILT_IN)
def test_image_method_with_zero_lambda_is_the_plain_render_at_every_iteration(busy_scene, mapping, spp):
    plain = paint(busy_scene, CAMERA, W, H, PaintParams(iterations=1, spp=spp, seed=2)).state
    params = PaintParams(mapping=mapping, method="image", iterations=4, spp=spp, seed=2, lambda_p=0.0, noise=0.5)
    result = paint(busy_scene, CAMERA, W, H, params, keep_iterations=True)
    for image in result.iterations:
        np.testing.assert_array_equal(image, plain.image())
    moved = paint(busy_scene, CAMERA, W, H, replace(params, lambda_p=6.0, noise=0.0), keep_iterations=True)
    np.testing.assert_array_equal(moved.iterations[0], plain.image())  # iteration 1 is traced
    assert not np.array_equal(moved.image, plain.image())


@pytest.mark.parametrize("mapping", ["color", "depth"])
def test_image_method_equals_ray_tracing_where_lookups_stay_on_a_facing_plane(gradient_scene, mapping):
    # the plane's albedo is linear in x and y, so a bilinear lookup between pixel centres is what a ray sees;
    # lambda_p 3 (times |z - z0| = 2 for depth) keeps every lookup within 6 pixels of its own
    common = dict(mapping=mapping, iterations=5, lambda_p=3.0, z0=2.0)
    traced = paint(gradient_scene, CAMERA, W, H, PaintParams(**common), keep_iterations=True)
    looked = paint(gradient_scene, CAMERA, W, H, PaintParams(method="image", **common), keep_iterations=True)
    inner = (slice(7, H - 7), slice(7, W - 7))
    for a, b in zip(traced.iterations, looked.iterations, strict=True):
        np.testing.assert_allclose(b[inner], a[inner], rtol=0, atol=2e-5)
    assert np.abs(traced.image - traced.iterations[0])[inner].max() > 0.01  # it did move
    if mapping == "depth":
        np.testing.assert_allclose(looked.state.depth, 4.0, rtol=1e-6)


def test_image_method_depth_of_a_miss_is_z_max():
    sky = make_scene([], sky=(0.9, 0.1, 0.5), z_max=37.5)
    params = PaintParams(mapping="depth", method="image", iterations=3, lambda_p=5.0)
    assert np.all(paint(sky, CAMERA, W, H, params).state.depth == np.float32(37.5))


def test_image_method_refuses_a_partial_region(busy_scene):
    with pytest.raises(ValueError, match="full image"):
        paint(busy_scene, CAMERA, W, H, PaintParams(method="image"), region=Region(W, H, 0, 0, W, 8))


def test_image_method_temporal_mode_continues_the_lookups(busy_scene):
    params = PaintParams(mapping="depth", method="image", spp=2, noise=0.2, iterations=3, edge="wrap")
    first = paint(busy_scene, CAMERA, W, H, params)
    second = paint(busy_scene, CAMERA, W, H, params, previous=first.state, keep_iterations=True)
    at_once = paint(busy_scene, CAMERA, W, H, replace(params, iterations=6))
    np.testing.assert_array_equal(second.image, at_once.image)
    np.testing.assert_array_equal(second.state.depth, at_once.state.depth)
    assert len(second.iterations) == 3 and not np.array_equal(first.image, at_once.image)
    # with a new camera, the lookups read the new camera's plain render
    moved = CAMERA.moved(eye=(0.3, 0.0, 0.0), look_at=(0.3, 0.0, -1.0))
    temporal = paint(busy_scene, moved, W, H, replace(params, iterations=1, lambda_p=0.0), previous=first.state)
    plain = paint(busy_scene, moved, W, H, PaintParams(spp=2, iterations=1))
    np.testing.assert_array_equal(temporal.image, plain.image)


def test_image_method_on_a_shared_pool_and_abandoned_between_iterations(busy_scene):
    params = PaintParams(method="image", iterations=4, lambda_p=7.0)
    alone = paint(busy_scene, CAMERA, W, H, params, threads=1)
    with ThreadPoolExecutor(2) as pool:
        shared = paint(busy_scene, CAMERA, W, H, params, pool=pool, threads=2)
    np.testing.assert_array_equal(shared.image, alone.image)
    asked = []

    def stop():
        asked.append(1)
        return len(asked) > 5

    with pytest.raises(Abandoned):
        paint(busy_scene, CAMERA, W, H, params, threads=1, should_stop=stop)
