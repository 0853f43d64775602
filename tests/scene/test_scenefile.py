"""Scene files: valid TOML loads; a broken file is one SceneError line naming the file; names stay inside."""

import logging
import math

import numpy as np
import pytest
import trimesh
from PIL import Image

from rcp_server.camera.camera import Camera
from rcp_server.painting.loop import paint
from rcp_server.scene.scenefile import SCENE_NAME, SceneError, load_scene, load_scene_file, scene_names
from rcp_server.settings.params import PaintParams

VALID = """\
title = "A red ball"
z_max = 50.0

[camera]
eye = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
fov = 40

[environment]
color = [0.2, 0.3, 0.4]

[paint]
mapping = "depth"
iterations = 3
lambda_p = 4.0

[[objects]]
name = "ball"
primitive = { type = "sphere", radius = 1.0, subdivisions = 2 }
color = [1.0, 0.0, 0.0]

[[objects]]
name = "floor"
primitive = { type = "box", extents = [4.0, 0.1, 4.0] }
translate = [0.0, -1.5, 0.0]
instances = [{ translate = [0.0, 0.0, 0.0] }, { translate = [0.0, 0.0, -4.0] }]
"""


def _write(path, text):
    path.write_text(text)
    return path


def _one_line_error(path, exc_info):
    message = str(exc_info.value)
    assert "\n" not in message, message
    assert str(path) in message, message
    return message


def test_valid_scene_file_loads_and_renders(tmp_path):
    path = _write(tmp_path / "ball.toml", VALID)
    scene = load_scene_file(path)
    assert scene.name == "ball" and scene.title == "A red ball"
    assert scene.camera == Camera((0, 0, 5), (0, 0, 0), fov=40)
    assert scene.light is None and scene.z_max == 50.0 and scene.depth_of_miss(scene.camera.eye) == 50.0
    assert scene.paint == PaintParams(mapping="depth", iterations=3, lambda_p=4.0)
    np.testing.assert_array_equal(scene.environment.image, np.float32([[[0.2, 0.3, 0.4]]]))
    assert [len(o.instances) for o in scene.objects] == [1, 2]
    geometry, tracer = scene.geometry()
    assert tracer is not None and geometry.face_count == 320 + 2 * 12
    image = paint(scene, scene.camera, 32, 24, PaintParams(iterations=1)).image
    # unlit: the ball's centre is exactly its color, the corner sees the sky
    np.testing.assert_array_equal(image[12, 16], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(image[0, 0], [0.2, 0.3, 0.4], atol=1e-6)


def test_scene_by_name_and_scene_names(tmp_path):
    _write(tmp_path / "ball.toml", VALID)
    _write(tmp_path / "b-2_x.toml", VALID)
    _write(tmp_path / "bad name.toml", VALID)
    _write(tmp_path / ".hidden.toml", VALID)
    _write(tmp_path / "notes.txt", VALID)
    assert scene_names(tmp_path) == ["b-2_x", "ball"]
    scene = load_scene("ball", tmp_path)
    assert scene.name == "ball" and scene.title == "A red ball"
    with pytest.raises(SceneError) as info:
        load_scene("nope", tmp_path)
    assert "b-2_x, ball" in str(info.value) and "\n" not in str(info.value)


CAM = "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n"

BROKEN = {
    "bad_toml": "[camera\neye = [0, 0, 5]\n",
    "unknown_key": "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\nzoom = 2\n",
    "unknown_top_key": "colour = 1\n[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n",
    "wrong_type": '[camera]\neye = "up there"\nlook_at = [0, 0, 0]\n',
    "short_vector": "[camera]\neye = [0, 5]\nlook_at = [0, 0, 0]\n",
    "nan": "[camera]\neye = [nan, 0, 5]\nlook_at = [0, 0, 0]\n",
    "inf_translate": (
        "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\n"
        'primitive = { type = "box" }\ntranslate = [inf, 0, 0]\n'
    ),
    "missing_camera": "[environment]\ncolor = [0.1, 0.1, 0.1]\n",
    "degenerate_camera": "[camera]\neye = [1, 2, 3]\nlook_at = [1, 2, 3]\n",
    "up_parallel": "[camera]\neye = [0, 0, 0]\nlook_at = [0, 4, 0]\n",
    "color_out_of_range": CAM + "[environment]\ncolor = [2, 0, 0]\n",
    "both_env": CAM + '[environment]\ncolor = [1, 0, 0]\nimage = "x.png"\n',
    "missing_env_image": '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[environment]\nimage = "sky.png"\n',
    "zero_light": "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[light]\ndirection = [0, 0, 0]\n",
    "mesh_and_primitive": (
        '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nmesh = "m.obj"\nprimitive = { type = "box" }\n'
    ),
    "neither_mesh_nor_primitive": '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nname = "x"\n',
    "unknown_primitive": (
        '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nprimitive = { type = "torus" }\n'
    ),
    "missing_mesh": '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nmesh = "nope.obj"\n',
    "missing_texture": (
        "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\n"
        'primitive = { type = "grid" }\ntexture = "nope.png"\n'
    ),
    "texture_without_uv": (
        '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nprimitive = { type = "box" }\ntexture = "t.png"\n'
    ),
    "unknown_paint_key": "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[paint]\nsmudge = 3\n",
    "bad_paint_value": "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[paint]\niterations = 0\n",
    "negative_radius": (
        '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nprimitive = { type = "sphere", radius = -1.0 }\n'
    ),
    "not_utf8": b'title = "\xff\xfe"\n[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n',
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_scene_file_is_one_line_naming_the_file(tmp_path, case):
    Image.new("RGB", (2, 2)).save(tmp_path / "t.png")
    path = tmp_path / f"{case}.toml"
    content = BROKEN[case]
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(SceneError) as info:
        load_scene_file(path)
    _one_line_error(path, info)
    # the same through load_scene, by name and by path
    with pytest.raises(SceneError):
        load_scene(case, tmp_path)
    with pytest.raises(SceneError):
        load_scene(str(path))


def test_broken_scene_messages_say_what_is_wrong(tmp_path):
    def message(text):
        path = _write(tmp_path / "s.toml", text)
        with pytest.raises(SceneError) as info:
            load_scene_file(path)
        return _one_line_error(path, info)

    assert "zoom" in message(BROKEN["unknown_key"])
    assert "camera" in message(BROKEN["missing_camera"])
    assert "eye" in message(BROKEN["nan"])
    assert "mesh" in message(BROKEN["mesh_and_primitive"]) and "primitive" in message(BROKEN["mesh_and_primitive"])
    assert "nope.obj" in message(BROKEN["missing_mesh"])


def test_unreadable_scene_file(tmp_path):
    with pytest.raises(SceneError) as info:
        load_scene_file(tmp_path / "absent.toml")
    _one_line_error(tmp_path / "absent.toml", info)


def test_unknown_mapping_in_paint_lists_the_valid_ones(tmp_path):
    path = _write(tmp_path / "s.toml", '[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n[paint]\nmapping = "swirly"\n')
    with pytest.raises(SceneError) as info:
        load_scene_file(path)
    message = _one_line_error(path, info)
    assert "swirly" in message
    for name in ("color", "depth", "normal"):
        assert name in message


@pytest.mark.parametrize(
    "ref",
    ["../outside", "../outside.toml", "/etc/passwd", "a\x00b", "..", "scenes/../outside", "", ".", "~root"],
)
def test_a_path_is_never_taken_for_a_scene_name(tmp_path, monkeypatch, ref):
    folder = tmp_path / "scenes"
    folder.mkdir()
    _write(folder / "inside.toml", VALID)
    elsewhere = tmp_path / "work" / "deeper"  # the working directory is not beside the scenes folder
    elsewhere.mkdir(parents=True)
    monkeypatch.chdir(elsewhere)
    _write(tmp_path / "outside.toml", VALID)  # the file '../outside' would reach from the scenes folder
    assert not SCENE_NAME.fullmatch(ref)
    with pytest.raises(SceneError) as info:
        load_scene(ref, folder)
    assert "\n" not in str(info.value)
    assert "outside" not in scene_names(folder)


def test_scene_name_pattern():
    for good in ("default", "a", "City_2", "sea-waves"):
        assert SCENE_NAME.fullmatch(good)
    for bad in ("-x", "_x", "a.b", "a/b", "a\\b", "a b", "x" * 65, "ä", "a\n"):
        assert not SCENE_NAME.fullmatch(bad), bad


def _sun_lit(color, normal, light):
    """What the shading gives a lit surface: albedo * (ambient + (1 - ambient) * max(0, n . -direction))."""
    lambert = max(0.0, -float(np.dot(normal, light.direction)))
    return np.asarray(color) * (light.ambient + (1.0 - light.ambient) * lambert)


def test_bare_obj_with_vertex_colors_loads_as_a_lit_framed_scene(tmp_path):
    path = _write(
        tmp_path / "red.obj",
        "v -1 -1 0 1 0 0\nv 1 -1 0 1 0 0\nv -1 1 0 1 0 0\nv 1 1 0 1 0 0\nf 1 2 3\nf 2 4 3\n",
    )
    scene = load_scene(str(path))
    assert scene.title == "red.obj" and scene.light is not None
    image = paint(scene, scene.camera, 33, 25, PaintParams(iterations=1)).image
    expected = _sun_lit((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), scene.light)
    np.testing.assert_allclose(image[12, 16], expected, atol=1e-6)
    # the framing camera shows all of it: the border is sky
    np.testing.assert_allclose(image[0, 0], scene.environment.image[0, 0], atol=1e-6)


@pytest.mark.parametrize("kind", ["ply", "stl"])
def test_bare_ply_and_stl_load_and_render(tmp_path, kind):
    mesh = trimesh.creation.box(extents=(2, 2, 2))
    path = tmp_path / f"box.{kind}"
    path.write_bytes(mesh.export(file_type=kind))
    scene = load_scene(str(path))
    result = paint(scene, scene.camera, 32, 24, PaintParams(iterations=2))
    assert np.all(np.isfinite(result.image))
    # the centre pixel sees the box, not the sky
    assert not np.allclose(result.image[12, 16], scene.environment.image[0, 0], atol=1e-3)


def test_bad_bare_mesh_files_are_scene_errors(tmp_path):
    for name, content in (("g.obj", b"\x00\x01garbage"), ("e.obj", b"v 0 0 0\n"), ("g.glb", b"glTF junk")):
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(SceneError) as info:
            load_scene(str(path))
        _one_line_error(path, info)


def test_scene_file_with_missing_mtl_texture_still_renders(tmp_path, caplog):
    _write(tmp_path / "m.mtl", "newmtl m\nKd 0.2 0.6 0.4\nmap_Kd gone.png\n")
    _write(
        tmp_path / "m.obj",
        "mtllib m.mtl\nv -1 -1 0\nv 1 -1 0\nv -1 1 0\nv 1 1 0\n"
        "vt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nusemtl m\nf 1/1 2/2 3/3\nf 2/2 4/4 3/3\n",
    )
    path = _write(tmp_path / "s.toml", '[camera]\neye = [0, 0, 4]\nlook_at = [0, 0, 0]\n[[objects]]\nmesh = "m.obj"\n')
    with caplog.at_level(logging.WARNING, logger="rcp"):
        scene = load_scene_file(path)
    assert any("texture" in r.getMessage() for r in caplog.records if r.name == "rcp")
    image = paint(scene, scene.camera, 32, 24, PaintParams(iterations=3)).image
    np.testing.assert_allclose(image[12, 16], [0.2, 0.6, 0.4], atol=1 / 255)


def test_scene_file_with_nan_mesh_vertices_is_repaired(tmp_path, caplog):
    _write(tmp_path / "m.obj", "v -1 -1 0\nv 1 -1 0\nv -1 1 0\nv 1 1 0\nv nan 0 0\nf 1 2 3\nf 2 4 3\nf 3 4 5\n")
    path = _write(
        tmp_path / "s.toml",
        '[camera]\neye = [0, 0, 4]\nlook_at = [0, 0, 0]\n[[objects]]\nmesh = "m.obj"\ncolor = [0.5, 0.25, 1.0]\n',
    )
    with caplog.at_level(logging.WARNING, logger="rcp"):
        scene = load_scene_file(path)
    geometry, _ = scene.geometry()
    assert geometry.face_count == 2 and np.all(np.isfinite(geometry.triangles))
    image = paint(scene, scene.camera, 32, 24, PaintParams(iterations=3)).image
    assert np.all(np.isfinite(image))
    np.testing.assert_allclose(image[12, 16], [0.5, 0.25, 1.0], atol=1e-6)
    assert any("m.obj" in r.getMessage() for r in caplog.records if r.name == "rcp")


def test_glb_with_embedded_texture_round_trips_and_renders_the_texture_color(tmp_path):
    texel = np.array([200, 30, 60], np.uint8)
    image = Image.fromarray(np.broadcast_to(texel, (4, 4, 3)).copy())
    box = trimesh.creation.box(extents=(2, 2, 2))
    uv = np.random.default_rng(0).uniform(0.2, 0.8, (len(box.vertices), 2))
    box.visual = trimesh.visual.TextureVisuals(
        uv=uv, material=trimesh.visual.material.PBRMaterial(baseColorTexture=image)
    )
    path = tmp_path / "box.glb"
    path.write_bytes(box.export(file_type="glb"))
    scene = load_scene(str(path))
    geometry, _ = scene.geometry()
    assert len(geometry.texture_width) == 1 and geometry.texture_width[0] == 4 and np.all(geometry.texture_id == 0)
    np.testing.assert_array_equal(geometry.texels, np.broadcast_to(texel, (16, 3)))  # 8 bits, as the file has them
    scene.light = None  # unlit: a pixel shows the surface's color itself
    camera = Camera((0.0, 0.0, 6.0), (0.0, 0.0, 0.0), fov=30)
    result = paint(scene, camera, 32, 24, PaintParams(iterations=1))
    # glTF's base color factor defaults to 1: the face shows the texture's own color (filtered in linear light
    # and encoded back through a table: within 2e-4)
    np.testing.assert_allclose(result.image[12, 16], texel / 255.0, atol=2e-4)


def test_placement_rotates_scales_and_translates(tmp_path):
    path = _write(
        tmp_path / "s.toml",
        "[camera]\neye = [0, 0, 9]\nlook_at = [0, 0, 0]\n[[objects]]\n"
        'primitive = { type = "box", extents = [1, 2, 3] }\n'
        "rotate = [0, 90, 0]\nscale = 2.0\ntranslate = [1, 2, 3]\n",
    )
    tri = load_scene_file(path).geometry()[0].triangles.reshape(-1, 3)
    lo, hi = tri.min(axis=0), tri.max(axis=0)
    # a quarter turn about y swaps the x and z extents; the box's base sits at y = 0 before placement
    np.testing.assert_allclose(hi - lo, (6, 4, 2), atol=1e-5)
    np.testing.assert_allclose(lo, (1 - 3, 2, 3 - 1), atol=1e-5)
    assert math.isclose(float(hi[1]), 6.0, abs_tol=1e-5)


def test_scatter_that_cannot_place_every_copy_says_so(tmp_path, caplog):
    path = _write(
        tmp_path / "s.toml",
        '[camera]\neye = [0, 1, 5]\nlook_at = [0, 0, 0]\n[[objects]]\nname = "t"\nprimitive = { type = "box" }\n'
        "scatter = { count = 5, area = [-1, 1, -1, 1], keep_out = [[0, 0, 5]] }\n",
    )
    with caplog.at_level(logging.WARNING, logger="rcp"):
        scene = load_scene_file(path)
    assert [len(obj.instances) for obj in scene.objects] == [0]
    assert any("scatter placed 0 of 5" in r.getMessage() for r in caplog.records if r.name == "rcp")


PER_OBJECT_SCENE = """
[camera]
eye = [0, 1.2, 3.2]
look_at = [0, 0.8, 0]
[environment]
color = [0.3, 0.5, 0.8]
[light]
direction = [-0.5, -1, -0.4]
ambient = 0.2
[paint]
lambda_p = 10.0
iterations = 4
[materials.clay]
shading = "toon"
bands = 2
paint = { mapping = "normal", lambda_p = 16.0 }
[[objects]]
name = "figure"
primitive = { type = "sphere", radius = 0.7 }
translate = [-0.8, 0.7, 0]
color = [0.9, 0.3, 0.2]
paint = { lambda_p = 0 }
[[objects]]
name = "pot"
primitive = { type = "sphere", radius = 0.7 }
translate = [0.8, 0.7, 0]
material = "clay"
[[objects]]
name = "floor"
primitive = { type = "grid", size = [8, 8] }
material = "clay"
paint = { lambda_p = 3 }
"""


def test_a_scene_file_paints_per_object_and_per_material(tmp_path):
    path = tmp_path / "figures.toml"
    path.write_text(PER_OBJECT_SCENE)
    scene = load_scene_file(path)
    assert scene.paint.non_defaults()["objects"] == {"figure": {"lambda_p": 0}, "floor": {"lambda_p": 3}}
    assert scene.paint.non_defaults()["materials"] == {"clay": {"mapping": "normal", "lambda_p": 16.0}}
    # the file's painting is the engine's with the same settings given in code
    given = PaintParams(
        lambda_p=10.0,
        iterations=4,
        objects={"figure": {"lambda_p": 0}, "floor": {"lambda_p": 3}},
        materials={"clay": {"mapping": "normal", "lambda_p": 16.0}},
    )
    assert scene.paint == given
    painted = paint(scene, scene.camera, 64, 40, scene.paint).image
    plain = paint(scene, scene.camera, 64, 40, PaintParams(iterations=1)).image
    shows = paint(scene, scene.camera, 64, 40, PaintParams(iterations=1, objects={"figure": {}})).state.object
    figure, pot = ((shows == scene.geometry()[0].object_names.index(n)).reshape(40, 64) for n in ("figure", "pot"))
    assert figure.mean() > 0.05
    np.testing.assert_array_equal(painted[figure], plain[figure])  # the figure stays sharp
    assert (np.abs(painted - plain).max(axis=2) > 2 / 255)[pot].mean() > 0.2  # the clay pot is painted
    # the clay is toon-shaded: its lit side in two flat bands, so few distinct shades on the pot
    geometry = scene.geometry()[0]
    assert list(geometry.material_bands) == [0, 2] and geometry.material_names == ["", "clay"]


def test_a_scene_file_refuses_unknown_materials_and_settings(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(PER_OBJECT_SCENE.replace('material = "clay"\npaint = { lambda_p = 3 }', 'material = "glass"'))
    with pytest.raises(SceneError, match=r"objects.2 \(floor\): no material 'glass' in \[materials\]"):
        load_scene_file(path)
    path.write_text(PER_OBJECT_SCENE.replace("paint = { lambda_p = 0 }", "paint = { spp = 4 }"))
    with pytest.raises(SceneError, match="objects.figure: spp cannot vary per pixel"):
        load_scene_file(path)
