"""What the shading records: depth, normal, lighting, the environment, and only the channels a mapping reads."""

import math

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, facing_plane, hit_points, make_scene, sphere

from rcp_server.camera.camera import Camera, Region
from rcp_server.painting.loop import paint
from rcp_server.scene.scene import Environment, Light
from rcp_server.settings.params import PaintParams


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
    hits = hit_points(state, camera)
    np.testing.assert_allclose(hits[:, 2], -4.0, atol=2e-5)  # on the plane z = -4
    _, _, f = camera.basis()
    np.testing.assert_allclose(state.depth, (hits - np.asarray(camera.eye)) @ f, rtol=1e-6)


def test_recorded_normal_of_a_sphere_is_radial():
    center, radius = np.array([0.3, -0.2, -4.0]), 1.5
    scene = make_scene([sphere(tuple(center), radius, subdivisions=5)], z_max=1000.0)
    state = paint(scene, CAMERA, 64, 48, PaintParams(mapping="test-probe", iterations=1)).state
    hit = state.depth < 1000.0
    assert hit.sum() > 500
    points = hit_points(state)[hit]
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
