"""Broken input: NaN and degenerate geometry, non-finite displacements."""

import math

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, facing_plane, make_scene

from rcp_server.painting.loop import paint
from rcp_server.scene.meshes import Part
from rcp_server.scene.scene import Light, SceneObject
from rcp_server.settings.mappings import register_mapping
from rcp_server.settings.params import PaintParams


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


@pytest.mark.parametrize("method", ["raytrace", "image"])
def test_non_finite_displacements_move_nothing_in_either_method(busy_scene, method):
    @register_mapping("test-broken", reads={"color"})
    def broken(data):
        d = data.color_field().astype(np.float64) * 3.0
        d[::2] = np.nan
        d[1::4] = np.inf
        return d

    plain = paint(busy_scene, CAMERA, W, H, PaintParams(iterations=1)).image.reshape(-1, 3)
    # a ray that does not move is the plain render's to the bit
    params = PaintParams(mapping="test-broken", method=method, lambda_p=6.0)
    image = paint(busy_scene, CAMERA, W, H, params).image
    image = image.reshape(-1, 3)
    assert np.all(np.isfinite(image))
    np.testing.assert_array_equal(image[::2], plain[::2])
    np.testing.assert_array_equal(image[1::4], plain[1::4])
    assert not np.array_equal(image[3::4], plain[3::4])
