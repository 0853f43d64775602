"""The recursion: exact invariants of shared/MISSION.md on tiny scenes built in code."""

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest
from conftest import CAMERA, facing_plane, gradient, make_scene, sphere, translate

from rcp_server.camera import Camera, Region
from rcp_server.mappings import MAPPINGS, register_mapping
from rcp_server.meshes import Part
from rcp_server.painting import Abandoned, PaintState, _frame, displacements, paint
from rcp_server.params import PaintParams
from rcp_server.scene import Environment, Light, SceneObject

W, H = 48, 32
MAPPING_NAMES = ("color", "depth", "normal")


def _state(region, color, depth=None, normal=None, direction=None) -> PaintState:
    n = region.pixel_count

    def full(value, shape):
        return None if value is None else np.ascontiguousarray(np.broadcast_to(np.float32(value), shape))

    return PaintState(region, full(color, (n, 3)), full(depth, (n,)), full(normal, (n, 3)), full(direction, (n, 3)))


def _hits(state: PaintState, camera: Camera = CAMERA) -> np.ndarray:
    """World hit points from a state that recorded depth and direction (spp = 1): (n, 3) float64."""
    r, u, f = camera.basis()
    direction = state.direction.astype(np.float64)
    along = state.depth.astype(np.float64) / (direction @ f)
    return np.asarray(camera.eye) + along[:, None] * direction


# ---- the plain render and lambda = 0 ----


@pytest.mark.parametrize("mapping", MAPPING_NAMES + ("test-probe",))
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
@pytest.mark.parametrize("mapping", MAPPING_NAMES)
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
    v_p, v_e = displacements(result.state, _frame(CAMERA, region, params), params, 1.0)
    assert np.all(v_p == 0.0) and np.all(v_e == 0.0)
    # the rays themselves: every recorded direction is the plain primary ray's
    probe = PaintParams(mapping="color", eye_mapping="test-probe", lambda_p=30.0, lambda_e=1.0, iterations=4)
    state = paint(grey, CAMERA, W, H, probe).state
    i, j = region.pixel_coords()
    plane = _frame(CAMERA, region, probe).plane()
    primary = plane - np.asarray(CAMERA.eye)
    primary /= np.linalg.norm(primary, axis=1, keepdims=True)
    np.testing.assert_allclose(state.direction, primary, rtol=0, atol=1e-7)


# ---- the color mapping moves rays the stated way ----


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
    v_p, v_e = displacements(_state(region, color), _frame(camera, region, params), params, 4.0)
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
    shift = _hits(moved) - _hits(plain)
    # the target moved 2.5 p along r on the unit-distance plane, so 4 * 2.5 p on the plane at depth 4
    expected = np.broadcast_to(4.0 * 2.5 * CAMERA.pixel_pitch(H) * np.array([1.0, 0.0, 0.0]), shift.shape)
    np.testing.assert_allclose(shift, expected, rtol=0, atol=2e-5)


# ---- depth, normal and eye mappings ----


def test_pixels_at_the_focus_depth_do_not_move():
    region = Region(W, H)
    rng = np.random.default_rng(0)
    colors = rng.uniform(0, 1, (region.pixel_count, 3)).astype(np.float32)
    params = PaintParams(mapping="depth", lambda_p=9.0)
    state = PaintState(region, colors, np.full(region.pixel_count, 3.25, np.float32))
    v_p, _ = displacements(state, _frame(CAMERA, region, params), params, 3.25)
    assert np.all(v_p == 0.0)
    v_p, _ = displacements(state, _frame(CAMERA, region, params), params, 4.25)
    np.testing.assert_allclose(
        v_p,
        displacements(PaintState(region, colors), _frame(CAMERA, region, params), PaintParams(lambda_p=9.0), 0.0)[0],
        rtol=1e-6,
        atol=1e-12,
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
    v_p, _ = displacements(state, _frame(CAMERA, region, params), params, 1.0)
    assert np.all(v_p == 0.0)
    # a miss records no normal and displaces nothing
    state = PaintState(region, state.color, None, np.zeros_like(direction), direction)
    assert np.all(displacements(state, _frame(CAMERA, region, params), params, 1.0)[0] == 0.0)


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
    plain_hits = _hits(plain)
    # the origin moved by lambda_e r; depth is still measured from the frame's eye along f
    moved_hits = _hits(moved) + 0.25 * r
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


# ---- what the shading records ----


def test_recorded_depth_of_a_facing_plane_is_its_distance_and_a_miss_is_z_max():
    scene = make_scene([facing_plane(5.0, size=(4.0, 4.0), divisions=(2, 2))], z_max=77.0)
    for spp in (1, 4):
        state = paint(scene, CAMERA, W, H, PaintParams(mapping="depth", iterations=2, spp=spp, lambda_p=0.0)).state
        # the plane spans |x|, |y| < 2 at depth 5: pixel centres inside that square hit it
        hit = np.abs(state.depth - 5.0) < 1e-5
        miss = state.depth == np.float32(77.0)
        assert hit.sum() > 100 and miss.sum() > 100
        if spp == 1:
            assert (hit | miss).all()
    state = paint(scene, CAMERA, W, H, PaintParams(mapping="depth", iterations=1)).state
    i, j = Region(W, H).pixel_coords()
    tan_half = math.tan(math.radians(30.0))
    x = (2 * (i + 0.5) / W - 1) * (W / H) * tan_half * 5.0
    y = (1 - 2 * (j + 0.5) / H) * tan_half * 5.0
    inside = (np.abs(x) < 1.99) & (np.abs(y) < 1.99)
    outside = (np.abs(x) > 2.01) | (np.abs(y) > 2.01)
    np.testing.assert_allclose(state.depth[inside], 5.0, rtol=1e-6)
    assert np.all(state.depth[outside] == np.float32(77.0))


def test_recorded_depth_of_a_tilted_camera_is_along_its_forward_axis():
    camera = Camera((3.0, 1.0, 2.0), (0.0, 0.0, -4.0))
    scene = make_scene([facing_plane(4.0, size=(60.0, 60.0))], camera=camera)
    state = paint(scene, camera, W, H, PaintParams(mapping="test-probe", iterations=1)).state
    hits = _hits(state, camera)
    np.testing.assert_allclose(hits[:, 2], -4.0, atol=2e-5)  # on the plane z = -4
    _, _, f = camera.basis()
    np.testing.assert_allclose(state.depth, (hits - np.asarray(camera.eye)) @ f, rtol=1e-6)


def test_recorded_normal_of_a_sphere_is_radial():
    center, radius = np.array([0.3, -0.2, -4.0]), 1.5
    scene = make_scene([sphere(tuple(center), radius, subdivisions=5)], z_max=1000.0)
    state = paint(scene, CAMERA, 64, 48, PaintParams(mapping="test-probe", iterations=1)).state
    hit = state.depth < 1000.0
    assert hit.sum() > 500
    points = _hits(state)[hit]
    radial = (points - center) / radius
    # the hit lies on the flat tessellation, inside the sphere by at most its sagitta
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), 1.0, atol=1e-3)
    # smooth shading: within an eighth of an edge's angle (about 0.035 rad at 5 subdivisions) of the true
    # normal; flat face normals would be off by up to a third of it
    edge = 1.1071487 / 2**5
    np.testing.assert_allclose(state.normal[hit], radial, atol=edge / 8)
    np.testing.assert_allclose(np.linalg.norm(state.normal[hit], axis=1), 1.0, atol=1e-6)
    assert np.all(state.normal[~hit] == 0.0)
    # the sphere's normals face the camera
    assert np.all(np.einsum("nk,nk->n", state.normal[hit], state.direction[hit]) < 0)


def test_recorded_normal_of_a_plane_and_lighting():
    light = Light(tuple(np.array([0.0, -1.0, -1.0]) / math.sqrt(2.0)), 0.2)
    scene = make_scene([facing_plane(3.0, color=(0.8, 0.6, 0.4))], light=light)
    state = paint(scene, CAMERA, W, H, PaintParams(mapping="normal", iterations=1)).state
    np.testing.assert_allclose(state.normal, np.broadcast_to([0.0, 0.0, 1.0], state.normal.shape), atol=1e-6)
    # albedo * (ambient + (1 - ambient) * n . -l) with n . -l = cos 45 degrees
    expected = np.float32([0.8, 0.6, 0.4]) * (0.2 + 0.8 * math.sqrt(0.5))
    np.testing.assert_allclose(state.color, np.broadcast_to(expected, state.color.shape), atol=1e-6)
    # seen from behind (two-sided shading), the light from the front does not reach: ambient only
    back = Camera((0.0, 0.0, -6.0), (0.0, 0.0, 0.0))
    image = paint(scene, back, W, H, PaintParams(iterations=1)).image
    np.testing.assert_allclose(image[H // 2, W // 2], np.float32([0.8, 0.6, 0.4]) * 0.2, atol=1e-6)


def test_environment_orientation():
    rows, cols = 64, 128
    x = (np.arange(cols) + 0.5) / cols
    y = (np.arange(rows) + 0.5) / rows
    image = np.stack(
        [
            np.broadcast_to(x, (rows, cols)),
            np.broadcast_to(y[:, None], (rows, cols)),
            np.full((rows, cols), 0.5),
        ],
        axis=2,
    ).astype(np.float32)
    scene = make_scene([], environment=Environment(image))
    for look, expected in (
        ((0, 0, -1), (0.5, 0.5)),
        ((1, 0, 0), (0.75, 0.5)),
        ((-1, 0, 0), (0.25, 0.5)),
        ((0, 0.5, -1), (0.5, 0.5 - math.atan(0.5) / math.pi)),
        ((0, -1, -1), (0.5, 0.75)),
    ):
        camera = Camera((0.0, 0.0, 0.0), look)
        pixel = paint(scene, camera, 1, 1, PaintParams(iterations=1)).image[0, 0]
        np.testing.assert_allclose(pixel[:2], expected, atol=1e-4)
    # straight up is the top row
    up = Camera((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), up=(0.0, 0.0, -1.0))
    assert paint(scene, up, 1, 1, PaintParams(iterations=1)).image[0, 0, 1] == pytest.approx(0.5 / rows, abs=1e-4)


# ---- seeds, tiles, threads, time ----


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
    params = PaintParams(mapping="color", iterations=1, lambda_p=5.0)
    state = None
    for _ in range(4):
        state = paint(busy_scene, CAMERA, W, H, params, previous=state).state
    at_once = paint(busy_scene, CAMERA, W, H, PaintParams(mapping="color", iterations=4, lambda_p=5.0)).state
    np.testing.assert_array_equal(state.color, at_once.color)


# ---- broken geometry ----


def _bad_faces() -> SceneObject:
    """Zero-area, NaN and infinite triangles around (1.5, 1, -3), with one good triangle among them."""
    nan, inf = float("nan"), float("inf")
    v = np.array(
        [
            [1.4, 0.9, -3.0],
            [1.6, 0.9, -3.0],
            [1.8, 0.9, -3.0],  # collinear: zero area
            [nan, 1.0, -3.0],
            [1.5, 1.1, -3.0],
            [1.6, 1.0, -3.0],  # NaN corner
            [1.5, 1.0, -3.0],
            [1.5, 1.0, -3.0],
            [1.5, 1.0, -3.0],  # a point
            [inf, 1.0, -3.0],
            [1.4, 1.2, -3.0],
            [1.6, 1.2, -3.0],  # infinite corner
            [nan, nan, nan],
            [nan, nan, nan],
            [nan, nan, nan],  # all NaN
        ]
    )
    part = Part(v, np.arange(15).reshape(5, 3), np.full((5, 3, 3), 0.7, np.float32))
    return SceneObject("bad", part, [(np.eye(4), part)])


def _pixel_of(point, width, height):
    x, y, z = point
    tan_half = math.tan(math.radians(30.0))
    return ((x / -z) / (tan_half * width / height) + 1) / 2 * width, (1 - (y / -z) / tan_half) / 2 * height


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # NaN input warns in numpy; expected
@pytest.mark.parametrize(
    "params",
    [
        PaintParams(iterations=4, lambda_p=4.0),
        PaintParams(mapping="normal", iterations=4, lambda_p=4.0, lambda_e=0.05),
        PaintParams(mapping="depth", iterations=4, lambda_p=4.0, spp=2, noise=0.3),
    ],
)
def test_nan_and_degenerate_geometry_neither_crashes_nor_poisons_pixels(busy_scene, params):
    light = busy_scene.light
    good = make_scene(busy_scene.objects, light=light, environment=busy_scene.environment, z_max=30.0)
    bad = make_scene(busy_scene.objects + [_bad_faces()], light=light, environment=busy_scene.environment, z_max=30.0)
    assert bad.geometry()[0].face_count == good.geometry()[0].face_count + 5  # the bad faces reach Embree
    clean = paint(good, CAMERA, W, H, params)
    broken = paint(bad, CAMERA, W, H, params)
    for name in ("color", "depth", "normal", "direction"):
        value = getattr(broken.state, name)
        assert value is None or np.all(np.isfinite(value)), name
    px, py = _pixel_of((1.5, 1.0, -3.0), W, H)
    j, i = np.mgrid[0:H, 0:W]
    far = np.hypot(i + 0.5 - px, j + 0.5 - py) > 12
    assert far.sum() > 0.7 * W * H
    np.testing.assert_array_equal(broken.image[far], clean.image[far])


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # NaN input warns in numpy; expected
def test_a_part_mixing_good_and_nan_faces_renders_its_good_faces():
    grid = facing_plane(4.0, size=(4.0, 4.0), divisions=(2, 2), color=(0.3, 0.6, 0.9))
    part = grid.part
    world = grid.instances[0][0]
    v = np.concatenate([part.vertices, [[np.nan, 0.0, 0.0], [0.1, 0.0, 0.1], [0.2, 0.0, 0.0]]])
    faces = np.concatenate([part.faces, [[len(v) - 3, len(v) - 2, len(v) - 1]]])
    colors = np.concatenate([part.corner_colors, part.corner_colors[:1]])
    mixed = Part(v, faces, colors, None, None)
    light = Light((0.0, 0.0, -1.0), 0.5)
    scene = make_scene([SceneObject("mixed", mixed, [(world, mixed)])], light=light)
    reference = make_scene([SceneObject("grid", part, [(world, part)])], light=light)
    a = paint(scene, CAMERA, W, H, PaintParams(mapping="normal", iterations=3)).image
    b = paint(reference, CAMERA, W, H, PaintParams(mapping="normal", iterations=3)).image
    assert np.all(np.isfinite(a))
    np.testing.assert_array_equal(a, b)


# ---- custom mappings and recorded channels ----

_calls = []


@register_mapping("test-painting-right", reads={"depth"})
def _right(data):
    """Every pixel moves right, whatever it saw."""
    _calls.append((data.depth is not None, data.normal is None, data.direction is None, len(data.color)))
    return np.tile(data.right, (len(data.color), 1))


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


@pytest.mark.parametrize(
    "params,recorded",
    [
        (PaintParams(mapping="color"), set()),
        (PaintParams(mapping="depth"), {"depth"}),
        (PaintParams(mapping="normal"), {"normal", "direction"}),
        (PaintParams(mapping="color", eye_mapping="depth", lambda_e=0.0), set()),
        (PaintParams(mapping="color", eye_mapping="depth", lambda_e=0.1), {"depth"}),
        (PaintParams(mapping="depth", eye_mapping="normal", lambda_e=0.1), {"depth", "normal", "direction"}),
        (PaintParams(mapping="test-probe"), {"depth", "normal", "direction"}),
    ],
)
def test_only_the_channels_the_mapping_reads_are_recorded(busy_scene, params, recorded):
    state = paint(busy_scene, CAMERA, 16, 12, params).state
    assert state.color is not None and state.color.shape == (16 * 12, 3)
    for channel in ("depth", "normal", "direction"):
        assert (getattr(state, channel) is not None) == (channel in recorded), channel
    assert params.reads() == recorded | {"color"}


# ---- parameters ----


def test_paint_params_validation():
    with pytest.raises(ValueError) as info:
        PaintParams(mapping="nope")
    assert all(name in str(info.value) for name in MAPPING_NAMES)
    with pytest.raises(ValueError):
        PaintParams(eye_mapping="nope")
    for bad in (
        {"iterations": 0},
        {"spp": 0},
        {"lambda_p": float("nan")},
        {"lambda_e": float("inf")},
        {"z0": float("nan")},
        {"noise": -0.1},
        {"z_max": float("inf")},
    ):
        with pytest.raises(ValueError):
            PaintParams(**bad)
    with pytest.raises(ValueError, match="smudge"):
        PaintParams.from_dict({"smudge": 1})
    assert PaintParams.from_dict({"mapping": "depth", "iterations": 2}) == PaintParams(mapping="depth", iterations=2)
    assert PaintParams().iterations == 6 and "color" in MAPPINGS


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
    from concurrent.futures import ThreadPoolExecutor

    params = PaintParams(iterations=3, lambda_p=6.0)
    alone = paint(busy_scene, CAMERA, W, H, params).image
    with ThreadPoolExecutor(2) as pool:
        shared = paint(busy_scene, CAMERA, W, H, params, pool=pool, threads=2).image
    np.testing.assert_array_equal(shared, alone)


def test_should_stop_abandons_between_iterations(busy_scene):
    from rcp_server.painting import Abandoned

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


# ---- the image-space method ----


def test_paint_params_method_and_edge_validation():
    assert PaintParams().method == "raytrace" and PaintParams().edge == "mirror"
    with pytest.raises(ValueError, match="raytrace, image"):
        PaintParams(method="raster")
    with pytest.raises(ValueError, match="clamp, wrap, mirror"):
        PaintParams(method="image", edge="repeat")
    with pytest.raises(ValueError, match="cannot represent eye displacement.*raytrace"):
        PaintParams(method="image", lambda_e=0.1)
    assert PaintParams.from_dict({"method": "image", "edge": "wrap"}) == PaintParams(method="image", edge="wrap")


@pytest.mark.parametrize("spp", [1, 3])
@pytest.mark.parametrize("mapping", MAPPING_NAMES)
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


@pytest.mark.parametrize("method", ["raytrace", "image"])
def test_non_finite_displacements_move_nothing_in_either_method(busy_scene, method):
    @register_mapping("test-broken", reads={"color"})
    def broken(data):
        d = data.color_field().astype(np.float64) * 3.0
        d[::2] = np.nan
        d[1::4] = np.inf
        return d

    plain = paint(busy_scene, CAMERA, W, H, PaintParams(iterations=1)).image.reshape(-1, 3)
    image = paint(busy_scene, CAMERA, W, H, PaintParams(mapping="test-broken", method=method, lambda_p=6.0)).image
    image = image.reshape(-1, 3)
    assert np.all(np.isfinite(image))
    np.testing.assert_array_equal(image[::2], plain[::2])
    np.testing.assert_array_equal(image[1::4], plain[1::4])
    assert not np.array_equal(image[3::4], plain[3::4])


def test_tiles_are_balanced_and_no_tile_holds_a_thread_for_long():
    from rcp_server.painting import TILE_WORK, tile_rows

    assert tile_rows(Region(640, 360), 2, 6) == 45  # four tiles a thread
    rows = tile_rows(Region(1280, 720), 2, 4 * 6)
    assert rows * 1280 * 4 * 6 <= TILE_WORK and (rows + 1) * 1280 * 4 * 6 > TILE_WORK
    assert tile_rows(Region(8000, 4), 2, 64 * 64) == 1  # a row is the least a tile can be
