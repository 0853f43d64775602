"""Where a model is seen from when its file says nothing: interiors from inside, figures from where they
face; and a scene file that names a glTF's camera and light. Every model is built in code."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from helpers.gltf import GltfBuilder, quaternion

from rcp_server.scene import framing
from rcp_server.scene.meshes import Model, Part, _grey, primitive
from rcp_server.scene.scenefile import load_scene_file, model_scene


def _part(mesh: trimesh.Trimesh, flip: bool = False) -> Part:
    faces = np.asarray(mesh.faces, np.int64)
    if flip:
        faces = faces[:, ::-1].copy()  # the faces turned inwards: a room's walls seen from inside
    return Part(np.asarray(mesh.vertices, np.float64), faces, _grey(len(faces)))


def _box(extents, at) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(at)
    return box


def _room() -> list[Part]:
    """A closed room 8 x 3 x 5 (x, y, z), floor at y = 0, with a table, a sofa and a cupboard."""
    shell = _part(_box((8.0, 3.0, 5.0), (0.0, 1.5, 0.0)), flip=True)
    furniture = [
        _box((1.6, 0.8, 0.9), (0.5, 0.4, 0.3)),  # table
        _box((2.2, 0.9, 0.9), (-2.5, 0.45, -1.8)),  # sofa
        _box((1.0, 2.2, 0.6), (3.3, 1.1, 2.0)),  # cupboard
    ]
    return [shell, *(_part(f) for f in furniture)]


def _figure(facing: float) -> list[Part]:
    """A standing figure that faces +z (facing 1) or -z (-1): a body, a head reaching forward, a tail behind."""
    body = _box((0.8, 1.4, 0.6), (0.0, 0.7, 0.0))
    head = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    head.apply_translation((0.0, 1.65, 0.45 * facing))
    nose = _box((0.1, 0.1, 0.2), (0.0, 1.65, 0.8 * facing))
    tail = _box((0.15, 0.15, 0.9), (0.0, 0.25, -0.7 * facing))
    return [_part(m) for m in (body, head, nose, tail)]


def test_a_closed_room_is_seen_from_inside_at_a_third_of_its_height_along_its_length():
    scene = model_scene(Model(_room()), "room", "room")
    eye, look_at = np.asarray(scene.camera.eye), np.asarray(scene.camera.look_at)
    assert np.all(np.abs(eye[[0, 2]]) < [4.0, 2.5])  # inside its walls
    assert eye[1] == pytest.approx(3.0 / 3)  # a third of the room's height above its floor
    forward = (look_at - eye) / np.linalg.norm(look_at - eye)
    np.testing.assert_allclose(np.abs(forward), [1, 0, 0], atol=1e-9)  # along the longest extent (x, 8)
    assert scene.camera.fov == framing.INTERIOR_FOV
    # the picture is the room: every pixel centre hits a wall, the floor or the furniture
    from rcp_server.painting.loop import paint
    from rcp_server.settings.params import PaintParams

    depth = paint(scene, scene.camera, 32, 18, PaintParams(iterations=1, mapping="depth")).state.depth
    assert np.all(depth < 8.5)


def test_a_room_open_at_the_top_still_encloses_its_centre_but_a_closed_figure_does_not():
    room = _room()
    open_top = room[0]
    keep = ~np.all(open_top.vertices[open_top.faces][:, :, 1] > 2.9, axis=1)  # drop the ceiling
    parts = [Part(open_top.vertices, open_top.faces[keep], open_top.corner_colors[keep]), *room[1:]]
    geometry, tracer = model_scene(Model(parts), "r", "r").geometry()
    assert framing.interior_camera(geometry, tracer) is not None  # the walls still enclose most directions
    sphere = primitive("sphere", subdivisions=3)  # from its centre every ray meets the backs of its faces
    scene = model_scene(Model([sphere]), "s", "s")
    assert framing.interior_camera(*scene.geometry()) is None
    assert scene.camera.eye[2] > 1.0  # seen from outside, from the front


@pytest.mark.parametrize("facing", [1.0, -1.0])
def test_a_figure_is_seen_and_lit_from_where_it_faces(facing):
    scene = model_scene(Model(_figure(facing)), "f", "f")
    geometry, _ = scene.geometry()
    assert framing.facing_sign(geometry) == facing
    center = geometry.bounds.mean(axis=0)
    assert np.sign(scene.camera.eye[2] - center[2]) == facing
    assert np.sign(scene.camera.eye[0] - center[0]) == facing  # a little to its right, as it sees it
    assert np.sign(-scene.light.direction[2]) == facing  # the light comes from the side it faces


def test_a_scene_file_names_a_gltf_camera_and_light(tmp_path):
    b = GltfBuilder()
    b.quad([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], material=b.material())
    b.camera("Overview", (0, 0, 5), yfov_degrees=35)
    b.camera("Close", (0, 0, 2))
    b.light("Sun", "directional", rotation=quaternion((1, 0, 0), -90))
    (tmp_path / "model.glb").write_bytes(b.glb())
    (tmp_path / "s.toml").write_text(
        'camera = "Close"\nlight = "Sun"\n[[objects]]\nmesh = "model.glb"\ntranslate = [10, 0, 0]\n'
    )
    scene = load_scene_file(tmp_path / "s.toml")
    assert scene.camera.eye == pytest.approx((10, 0, 2))  # placed with its object
    np.testing.assert_allclose(scene.light.direction, [0, -1, 0], atol=1e-9)
    assert list(scene.viewpoints) == ["Overview"] and scene.viewpoints["Overview"].fov == pytest.approx(35)
    (tmp_path / "bad.toml").write_text('camera = "Nowhere"\n[[objects]]\nmesh = "model.glb"\n')
    with pytest.raises(ValueError, match="no camera named 'Nowhere'.*'Overview'"):
        load_scene_file(tmp_path / "bad.toml")
