"""Seeds, tiles, threads and time: a tile is exactly a crop, temporal mode continues the recursion."""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, facing_plane, gradient, make_scene, translate

from rcp_server.camera.camera import Region
from rcp_server.painting.loop import Abandoned, PaintState, paint
from rcp_server.scene.scene import SceneObject
from rcp_server.settings.mappings import register_mapping
from rcp_server.settings.params import PaintParams


def test_same_seed_same_image_different_seed_differs(busy_scene):
    def run(seed):
        return paint(
            busy_scene,
            CAMERA,
            W,
            H,
            PaintParams(spp=4, seed=seed, noise=0.3, iterations=3),
            keep_iterations=True,
        )

    a, b, c = run(5), run(5), run(6)
    np.testing.assert_array_equal(a.image, b.image)
    assert not np.array_equal(a.image, c.image)
    # already the plain render differs: the sub-pixel jitter is seeded
    assert (np.abs(a.iterations[0] - c.iterations[0]).max(axis=2) > 0).sum() > 50


@register_mapping("test-painting-swirl", reads={"normal"})
def _swirl(data):
    return np.cross(data.forward, data.color_field()) + 0.5 * data.normal


TILE_CASES = {
    "color": PaintParams(iterations=4),
    "depth-spp4-noise": PaintParams(mapping="depth", spp=4, noise=0.5, iterations=4, seed=2),
    "normal-eye": PaintParams(mapping="normal", lambda_e=0.2, spp=2, iterations=3),
    "color-eye-depth-noise": PaintParams(
        mapping="color", eye_mapping="depth", lambda_e=0.05, noise=0.3, spp=3, iterations=3
    ),
    "custom": PaintParams(mapping="test-painting-swirl", lambda_e=0.1, noise=0.2, iterations=3),
}


@pytest.mark.parametrize("case", sorted(TILE_CASES))
def test_a_tile_equals_the_same_crop_of_the_full_image_exactly(busy_scene, case):
    params = TILE_CASES[case]
    width, height = 40, 30
    full = paint(busy_scene, CAMERA, width, height, params, threads=2).state
    assert not np.array_equal(
        full.color,
        paint(
            busy_scene, CAMERA, width, height, PaintParams(iterations=1, spp=params.spp, seed=params.seed)
        ).state.color,
    )
    region = Region(width, height, 7, 5, 19, 13)
    rows, cols = slice(5, 18), slice(7, 26)
    for threads in (1, 2):
        tile = paint(busy_scene, CAMERA, width, height, params, region=region, threads=threads).state
        assert tile.region == region and tile.image().shape == (13, 19, 3)
        np.testing.assert_array_equal(tile.image(), full.image()[rows, cols])
        for channel in ("depth", "normal", "direction"):
            whole, part = getattr(full, channel), getattr(tile, channel)
            assert (whole is None) == (part is None)
            if whole is not None:
                shape = (height, width) + whole.shape[1:]
                np.testing.assert_array_equal(part, whole.reshape(shape)[rows, cols].reshape(part.shape))
    single = paint(busy_scene, CAMERA, width, height, params, threads=1).state
    np.testing.assert_array_equal(single.color, full.color)


def test_temporal_mode_continues_the_recursion(busy_scene):
    params = PaintParams(mapping="depth", lambda_e=0.1, spp=2, noise=0.2, iterations=3)
    first = paint(busy_scene, CAMERA, W, H, params)
    second = paint(busy_scene, CAMERA, W, H, params, previous=first.state)
    at_once = paint(
        busy_scene, CAMERA, W, H, PaintParams(mapping="depth", lambda_e=0.1, spp=2, noise=0.2, iterations=6)
    )
    np.testing.assert_array_equal(second.image, at_once.image)
    np.testing.assert_array_equal(second.state.depth, at_once.state.depth)
    assert not np.array_equal(first.image, at_once.image)
    # a previous state of another region cannot continue: the canvas restarts
    other = paint(busy_scene, CAMERA, W, H, params, region=Region(W, H, 0, 0, W, 8)).state
    restarted = paint(busy_scene, CAMERA, W, H, params, previous=other)
    np.testing.assert_array_equal(restarted.image, first.image)


def test_temporal_mode_one_iteration_at_a_time(busy_scene):
    # one iteration at a time and four at once are the same recursion to the bit
    params = PaintParams(mapping="color", iterations=1, lambda_p=5.0)
    state = None
    for _ in range(4):
        state = paint(busy_scene, CAMERA, W, H, params, previous=state).state
    at_once = paint(busy_scene, CAMERA, W, H, replace(params, iterations=4)).state
    np.testing.assert_array_equal(state.color, at_once.color)


def test_paint_refuses_mismatched_regions(busy_scene):
    with pytest.raises(ValueError):
        paint(busy_scene, CAMERA, W, H, PaintParams(), region=Region(W + 1, H))
    with pytest.raises(ValueError):
        paint(busy_scene, CAMERA, W, H, PaintParams(), region=Region(W, H, 0, 0, W, 4), keep_iterations=True)


def test_animated_object_moves_with_time():
    plane = facing_plane(4.0, size=(40.0, 40.0), divisions=(1, 1))
    # motion acts in object space, where the grid's normal is +y: -y moves it away from the camera
    obj = SceneObject("mover", plane.part, plane.instances, motion=lambda time: translate(0.0, -time, 0.0))
    scene = make_scene([obj])
    assert scene.animated
    for time, depth in ((0.0, 4.0), (1.0, 5.0), (2.5, 6.5)):
        state = paint(scene, CAMERA, W, H, PaintParams(mapping="depth", iterations=2), time=time).state
        np.testing.assert_allclose(state.depth, depth, rtol=1e-6)
    # the static scene shares its geometry across times
    static = make_scene([facing_plane(4.0)])
    assert static.geometry(0.0)[0] is static.geometry(5.0)[0]


def test_temporal_mode_uses_the_new_frames_camera_and_time():
    plane = facing_plane(4.0, size=(40.0, 40.0), colors_of=gradient)
    mover = SceneObject("mover", plane.part, plane.instances, motion=lambda time: translate(0.0, -time, 0.0))
    scene = make_scene([mover])
    params = PaintParams(mapping="depth", iterations=2, lambda_p=5.0)
    first = paint(scene, CAMERA, W, H, params, time=0.0)
    moved_camera = CAMERA.moved(eye=(0.5, 0.2, 0.0), look_at=(0.5, 0.2, -1.0))
    # lambda = 0: continuing from any state is the new frame's plain render
    still = PaintParams(mapping="depth", iterations=1, lambda_p=0.0)
    np.testing.assert_array_equal(
        paint(scene, moved_camera, W, H, still, previous=first.state, time=1.0).image,
        paint(scene, moved_camera, W, H, still, time=1.0).image,
    )
    # and the recursion sees the new time's geometry: the plane is now at depth 5
    second = paint(scene, moved_camera, W, H, params, previous=first.state, time=1.0)
    np.testing.assert_allclose(second.state.depth, 5.0, rtol=1e-6)
    assert not np.array_equal(second.image, paint(scene, moved_camera, W, H, params, time=1.0).image)


def test_shared_pool_paints_the_same_pixels(busy_scene):

    params = PaintParams(iterations=3, lambda_p=6.0)
    alone = paint(busy_scene, CAMERA, W, H, params).image
    with ThreadPoolExecutor(2) as pool:
        shared = paint(busy_scene, CAMERA, W, H, params, pool=pool, threads=2).image
    np.testing.assert_array_equal(shared, alone)


def test_should_stop_abandons_between_iterations(busy_scene):

    asked = []

    def should_stop():
        asked.append(1)
        return len(asked) > 3  # let a few tile-iterations run, then stop

    with pytest.raises(Abandoned):
        paint(busy_scene, CAMERA, W, H, PaintParams(iterations=50), threads=1, should_stop=should_stop)
    assert len(asked) == 4  # asked before every iteration and stopped at the first yes


def test_resized_state_picks_the_nearest_pixel():
    region = Region(4, 2)
    color = np.arange(24, dtype=np.float32).reshape(8, 3)
    state = PaintState(region, color, depth=np.arange(8, dtype=np.float32))
    assert state.resized(4, 2) is state
    up = state.resized(8, 4)
    assert up.region == Region(8, 4)
    np.testing.assert_array_equal(up.depth.reshape(4, 8), np.repeat(np.repeat(state.depth.reshape(2, 4), 2, 0), 2, 1))
    down = up.resized(4, 2)
    np.testing.assert_array_equal(down.color, state.color)
    assert down.normal is None and not down.blank


def test_tiles_are_balanced_and_no_tile_holds_a_thread_for_long():
    from rcp_server.painting.loop import TILE_WORK, tile_rows

    assert tile_rows(Region(640, 360), 2, 6) == 45  # four tiles a thread
    rows = tile_rows(Region(1280, 720), 2, 4 * 6)
    assert rows * 1280 * 4 * 6 <= TILE_WORK and (rows + 1) * 1280 * 4 * 6 > TILE_WORK
    assert tile_rows(Region(8000, 4), 2, 64 * 64) == 1  # a row is the least a tile can be
