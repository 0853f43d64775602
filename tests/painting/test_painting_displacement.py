"""How each mapping moves the per-pixel cameras: the color, depth, normal and eye mappings, and a registered one."""

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, facing_plane, gradient, hit_points, make_scene

from rcp_server.camera.camera import Camera, Region
from rcp_server.painting.assign import displacements, setup_tile
from rcp_server.painting.loop import PaintState, paint
from rcp_server.settings.mappings import register_mapping
from rcp_server.settings.params import PaintParams


def _state(region, color, depth=None, normal=None, direction=None) -> PaintState:
    n = region.pixel_count

    def full(value, shape):
        return None if value is None else np.ascontiguousarray(np.broadcast_to(np.float32(value), shape))

    return PaintState(region, full(color, (n, 3)), full(depth, (n,)), full(normal, (n, 3)), full(direction, (n, 3)))


@pytest.mark.parametrize(
    "color,axis",
    [
        ((1.0, 0.5, 0.5), 0),
        ((0.5, 1.0, 0.5), 1),
        ((0.5, 0.5, 1.0), 2),
        ((0.0, 0.5, 0.5), 0),
        ((0.5, 0.0, 0.5), 1),
    ],
)
def test_color_displacement_is_lambda_p_pixels_along_the_basis(color, axis):
    camera = Camera((1.0, 2.0, 3.0), (-1.0, 0.5, -2.0), fov=50.0)
    region = Region(W, H)
    params = PaintParams(lambda_p=5.0, lambda_e=0.3)
    v_p, v_e = displacements(_state(region, color), setup_tile(camera, region, params), params, 4.0)
    basis = np.stack(camera.basis())
    sign = 1.0 if max(color) == 1.0 else -1.0
    p = camera.pixel_pitch(H)
    expected = np.broadcast_to(sign * 5.0 * p * basis[axis], v_p.shape)
    np.testing.assert_allclose(v_p, expected, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(v_p, axis=1), 5.0 * p, rtol=1e-6)
    np.testing.assert_allclose(v_e, np.broadcast_to(sign * 0.3 * basis[axis], v_e.shape), rtol=1e-6, atol=1e-12)


def test_red_moves_the_target_right_green_up_blue_in_on_the_image(gradient_scene):
    region = Region(W, H)
    plain = paint(gradient_scene, CAMERA, W, H, PaintParams(iterations=1)).image
    params = PaintParams(iterations=1, lambda_p=3.0)

    def painted(color):
        return paint(gradient_scene, CAMERA, W, H, params, previous=_state(region, color)).image

    # R = 1: pixel i now sees what pixel i + 3 saw (the target moved 3 pixels right)
    np.testing.assert_allclose(painted((1.0, 0.5, 0.5))[:, :-3], plain[:, 3:], rtol=0, atol=2e-6)
    # G = 1: pixel row j sees what row j - 3 saw (up)
    np.testing.assert_allclose(painted((0.5, 1.0, 0.5))[3:], plain[:-3], rtol=0, atol=2e-6)
    # R = 0, G = 0: left and down
    np.testing.assert_allclose(painted((0.0, 0.0, 0.5))[:-3, 3:], plain[3:, :-3], rtol=0, atol=2e-6)
    # B = 1: the target moves 3 p along f, so the view zooms in about the centre by 1 + 3p
    zoom = 1.0 + 3.0 * CAMERA.pixel_pitch(H)
    blue = painted((0.5, 0.5, 1.0))
    np.testing.assert_allclose(blue[..., :2] - 0.5, (plain[..., :2] - 0.5) / zoom, rtol=0, atol=2e-6)


def test_hit_point_moves_by_lambda_p_pixel_pitches_on_a_facing_plane(gradient_scene):
    region = Region(W, H)
    probe = PaintParams(mapping="color", eye_mapping="test-probe", lambda_e=1.0, iterations=1, lambda_p=2.5)
    plain = paint(gradient_scene, CAMERA, W, H, probe).state
    previous = _state(region, (1.0, 0.5, 0.5), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    moved = paint(gradient_scene, CAMERA, W, H, probe, previous=previous).state
    np.testing.assert_allclose(plain.depth, 4.0, rtol=1e-6)
    np.testing.assert_allclose(moved.depth, 4.0, rtol=1e-6)
    shift = hit_points(moved) - hit_points(plain)
    # the target moved 2.5 p along r on the unit-distance plane, so 4 * 2.5 p on the plane at depth 4
    expected = np.broadcast_to(4.0 * 2.5 * CAMERA.pixel_pitch(H) * np.array([1.0, 0.0, 0.0]), shift.shape)
    np.testing.assert_allclose(shift, expected, rtol=0, atol=2e-5)


def test_pixels_at_the_focus_depth_do_not_move():
    region = Region(W, H)
    rng = np.random.default_rng(0)
    colors = rng.uniform(0, 1, (region.pixel_count, 3)).astype(np.float32)
    params = PaintParams(mapping="depth", lambda_p=9.0)
    state = PaintState(region, colors, np.full(region.pixel_count, 3.25, np.float32))
    setup = setup_tile(CAMERA, region, params)
    v_p, _ = displacements(state, setup, params, 3.25)
    assert np.all(v_p == 0.0)
    v_p, _ = displacements(state, setup, params, 4.25)
    np.testing.assert_allclose(
        v_p, displacements(PaintState(region, colors), setup, PaintParams(lambda_p=9.0), 0.0)[0], rtol=1e-6, atol=1e-12
    )


def test_a_plane_at_the_focus_depth_stays_sharp(gradient_scene):
    plain = paint(gradient_scene, CAMERA, W, H, PaintParams(iterations=1)).image
    focused = paint(
        gradient_scene,
        CAMERA,
        W,
        H,
        PaintParams(mapping="depth", z0=4.0, lambda_p=12.0, iterations=4),
        keep_iterations=True,
    )
    for image in focused.iterations:
        np.testing.assert_allclose(image, plain, rtol=0, atol=1e-5)
    defocused = paint(
        gradient_scene, CAMERA, W, H, PaintParams(mapping="depth", z0=2.0, lambda_p=12.0, iterations=2)
    ).image
    assert np.abs(defocused - plain).max() > 1e-2


def test_normal_parallel_to_the_ray_gives_no_displacement():
    region = Region(W, H)
    rng = np.random.default_rng(1)
    direction = rng.normal(size=(region.pixel_count, 3)).astype(np.float32)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    params = PaintParams(mapping="normal", lambda_p=7.0)
    state = PaintState(region, np.zeros((region.pixel_count, 3), np.float32), None, -direction, direction)
    v_p, _ = displacements(state, setup_tile(CAMERA, region, params), params, 1.0)
    assert np.all(v_p == 0.0)
    # a miss records no normal and displaces nothing
    state = PaintState(region, state.color, None, np.zeros_like(direction), direction)
    assert np.all(displacements(state, setup_tile(CAMERA, region, params), params, 1.0)[0] == 0.0)


def test_normal_mapping_keeps_the_pixel_whose_ray_meets_the_plane_head_on(gradient_scene):
    width, height = 33, 25  # odd: the centre pixel's ray is exactly f, along the plane's normal
    plain = paint(gradient_scene, CAMERA, width, height, PaintParams(iterations=1)).image
    result = paint(
        gradient_scene,
        CAMERA,
        width,
        height,
        PaintParams(mapping="normal", lambda_p=6.0, iterations=4),
        keep_iterations=True,
    )
    for image in result.iterations:
        np.testing.assert_array_equal(image[12, 16], plain[12, 16])
    # elsewhere the rays slide along the plane: C x N = (x, y, -1) x (0, 0, 1) / |.| = (y, -x, 0) / |.|
    assert np.abs(result.image - plain).max() > 1e-3


def _two_depths():
    near = facing_plane(2.0, size=(1.2, 1.2), divisions=(1, 1), color=(0.9, 0.1, 0.1), name="near")
    far = facing_plane(6.0, colors_of=gradient, name="far", size=(30.0, 30.0))
    return make_scene([near, far])


def test_eye_displacement_moves_origins_by_lambda_e_times_the_field_and_changes_parallax():
    scene = _two_depths()
    region = Region(W, H)
    # target mapping: the probe (records hits, moves nothing); eye mapping: color, all pixels R = 1
    params = PaintParams(mapping="test-probe", lambda_p=1.0, eye_mapping="color", lambda_e=0.25, iterations=1)
    previous = _state(region, (1.0, 0.5, 0.5), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    plain = paint(scene, CAMERA, W, H, params).state
    moved = paint(scene, CAMERA, W, H, params, previous=previous).state
    r = np.array([1.0, 0.0, 0.0])
    plain_hits = hit_points(plain)
    # the origin moved by lambda_e r; depth is still measured from the frame's eye along f
    moved_hits = hit_points(moved) + 0.25 * r
    near = np.isclose(plain.depth, 2.0) & np.isclose(moved.depth, 2.0)
    far = np.isclose(plain.depth, 6.0) & np.isclose(moved.depth, 6.0)
    assert near.sum() > 100 and far.sum() > 1000  # pixels that saw the same plane both times
    # through the same image-plane point, at depth z the ray moved by lambda_e (1 - z) r: parallax
    for mask, z in ((near, 2.0), (far, 6.0)):
        expected = np.broadcast_to(0.25 * (1.0 - z) * r, (mask.sum(), 3))
        np.testing.assert_allclose(moved_hits[mask] - plain_hits[mask], expected, rtol=0, atol=2e-5)


def test_eye_displacement_changes_the_image_of_a_two_depth_scene():
    scene = _two_depths()
    plain = paint(scene, CAMERA, W, H, PaintParams(iterations=1)).image
    still = paint(scene, CAMERA, W, H, PaintParams(iterations=3, lambda_p=0.0, lambda_e=0.0)).image
    moving = paint(scene, CAMERA, W, H, PaintParams(iterations=3, lambda_p=0.0, lambda_e=0.3)).image
    np.testing.assert_array_equal(still, plain)
    changed = np.abs(moving - plain).max(axis=2) > 1e-3
    assert changed.sum() > 20


def test_default_focus_depth_is_the_distance_to_look_at(gradient_scene):
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -4.0))  # look_at on the plane: z0 = 4 by default
    plain = paint(gradient_scene, camera, W, H, PaintParams(iterations=1)).image
    focused = paint(gradient_scene, camera, W, H, PaintParams(mapping="depth", lambda_p=12.0, iterations=3)).image
    np.testing.assert_allclose(focused, plain, rtol=0, atol=1e-5)
    near = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0))  # z0 = 1: the plane is 3 units out of focus
    assert (
        np.abs(paint(gradient_scene, near, W, H, PaintParams(mapping="depth", lambda_p=12.0)).image - plain).max()
        > 1e-2
    )


_calls = []


@register_mapping("test-painting-right", reads={"depth"})
def _right(data):
    """Every pixel moves right (its own r_ij), whatever it saw."""
    _calls.append((data.depth is not None, data.normal is None, data.direction is None, len(data.color)))
    return data.right


def test_a_registered_mapping_is_used(gradient_scene):
    _calls.clear()
    plain = paint(gradient_scene, CAMERA, W, H, PaintParams(iterations=1)).image
    result = paint(
        gradient_scene,
        CAMERA,
        W,
        H,
        PaintParams(mapping="test-painting-right", lambda_p=3.0, iterations=3),
        threads=1,
        keep_iterations=True,
    )
    np.testing.assert_array_equal(result.iterations[0], plain)
    for image in result.iterations[1:]:
        np.testing.assert_allclose(image[:, :-3], plain[:, 3:], rtol=0, atol=2e-6)
    assert _calls and all(c[:3] == (True, True, True) for c in _calls)
    assert sum(c[3] for c in _calls) == 2 * W * H  # iterations 2 and 3, every pixel once
    assert result.state.depth is not None and result.state.normal is None
