"""The channels beyond color, depth, normal and direction, against scenes whose answers are known: the object
and material indices of two boxes, the geometric normal of a coarse smooth sphere, texture coordinates and
world points on a facing plane. Each is recorded only when a painting reads it."""

from dataclasses import replace

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, facing_plane, hit_points, make_scene, sphere, translate

from rcp_server.engine.paintstate import CHANNELS
from rcp_server.painting.loop import paint
from rcp_server.scene.meshes import Material, primitive
from rcp_server.scene.scene import SceneObject
from rcp_server.settings.mappings import register_mapping, unregister_mapping
from rcp_server.settings.params import PaintParams


@pytest.fixture(scope="module")
def reads_everything():
    """An eye mapping that moves nothing and reads every channel, so that a painting records them all."""
    register_mapping("test-every-channel", CHANNELS, lambda data: np.zeros((len(data.color), 3)))
    yield PaintParams(iterations=1, lambda_p=0.0, lambda_e=1.0, eye_mapping="test-every-channel")
    unregister_mapping("test-every-channel")


def _box(name: str, x: float, color, material: Material) -> SceneObject:
    part = primitive("box", extents=(1.5, 1.5, 1.5)).tinted(color)
    part = replace(part, material=material)
    return SceneObject(f"{name}#0", part, [(translate(x, 0.0, -3.0), part)], label=name)


def test_object_and_material_of_two_boxes(reads_everything):
    stone, wood = Material(name="stone"), Material(name="wood", bands=2)
    scene = make_scene([_box("left", -1.0, (0.8, 0.2, 0.1), stone), _box("right", 1.0, (0.1, 0.3, 0.9), wood)])
    state = paint(scene, CAMERA, W, H, reads_everything).state
    geometry, _ = scene.geometry()
    assert geometry.object_names == ["left", "right"]
    position = state.position.astype(np.float64)
    hit = state.object >= 0
    assert 0.2 < hit.mean() < 0.8
    # the boxes span x in [-1.75, -0.25] and [0.25, 1.75]: a hit's own x says which it is
    np.testing.assert_array_equal(state.object[hit], np.where(position[hit, 0] < 0, 0, 1))
    names = np.array(geometry.material_names)[state.material[hit].astype(int)]
    np.testing.assert_array_equal(names, np.where(position[hit, 0] < 0, "stone", "wood"))
    np.testing.assert_array_equal(state.material[~hit], -1.0)
    # the unlit colour is the box's own, lit or not; a miss shows the sky's
    left, right = (obj.part.corner_colors[0, 0] for obj in scene.objects)
    np.testing.assert_allclose(state.albedo[hit], np.where(position[hit, :1] < 0, left, right), rtol=1e-6)
    # world points: on the boxes' surfaces, where depth and direction say the ray ended
    np.testing.assert_allclose(position[hit], hit_points(state)[hit], atol=1e-5)
    centre = np.where(position[hit, :1] < 0, -1.0, 1.0) * [1, 0, 0] + [0, 0.75, -3]  # a box stands on y = 0
    np.testing.assert_allclose(np.abs(position[hit] - centre).max(axis=1), 0.75, atol=1e-5)


def test_geometric_normal_of_a_smooth_sphere_is_its_triangles_own(reads_everything):
    scene = make_scene([sphere((0.0, 0.0, -4.0), 1.5, subdivisions=1)])
    state = paint(scene, CAMERA, W, H, reads_everything).state
    hit = state.object >= 0
    geometry, _ = scene.geometry()
    tri = geometry.triangles.astype(np.float64)
    faces = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    faces /= np.linalg.norm(faces, axis=1, keepdims=True)
    faces *= np.sign(np.einsum("fk,fk->f", faces, tri.mean(axis=1) - (0, 0, -4)))[:, None]  # outward
    g = state.geometric[hit].astype(np.float64)
    nearest = np.argmax(g @ faces.T, axis=1)
    np.testing.assert_allclose(g, faces[nearest], atol=1e-5)
    # the hit lies in the plane of that very triangle
    offset = np.einsum("nk,nk->n", state.position[hit] - tri[nearest, 0], faces[nearest])
    np.testing.assert_allclose(offset, 0.0, atol=1e-4)
    # and the shading normal, interpolated from the corners, is not it: the channel is a channel of its own
    apart = np.linalg.norm(state.normal[hit] - state.geometric[hit], axis=1)
    assert (apart > 0.02).mean() > 0.8


def test_texture_coordinates_of_a_facing_plane(reads_everything):
    scene = make_scene([facing_plane(4.0)])  # 16 x 16, uv from 0 to 1 across it
    state = paint(scene, CAMERA, W, H, reads_everything).state
    x, y = state.position[:, 0], state.position[:, 1]
    np.testing.assert_allclose(state.uv, np.stack([(x + 8) / 16, (y + 8) / 16], axis=1), atol=1e-5)


def test_channels_are_recorded_only_when_read():
    scene = make_scene([facing_plane(4.0)])
    state = paint(scene, CAMERA, W, H, PaintParams(iterations=2)).state
    assert state.recorded() == {"color"}
    per_object = PaintParams(iterations=2, objects={"plane": {"lambda_p": 0.0}})
    assert paint(scene, CAMERA, W, H, per_object).state.recorded() == {"color", "object"}
    noisy = PaintParams(iterations=2, surface_noise=0.5)
    assert paint(scene, CAMERA, W, H, noisy).state.recorded() == {"color", "position"}
