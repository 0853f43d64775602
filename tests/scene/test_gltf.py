"""glTF as its authors made it: cameras, lights, materials (factors, emission, unlit, alpha masks, texture
transforms), from files built in code (``helpers/gltf.py``); OBJ's map_d; and the sandbox's arrays carrying
all of it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers.gltf import GltfBuilder, quaternion
from PIL import Image

from rcp_server.camera.camera import Camera
from rcp_server.painting.loop import paint
from rcp_server.scene import gltf
from rcp_server.scene.meshes import load_model
from rcp_server.scene.scenefile import mesh_scene
from rcp_server.settings.params import PaintParams

BACK = [[-3, -2, -2], [3, -2, -2], [3, 2, -2], [-3, 2, -2]]  # a wall behind, facing +z
FRONT = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
CAMERA = Camera((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), fov=40.0)
W, H = 64, 48
# where x = -0.5 and x = +0.5 of the plane z = 0 fall in a W x H picture from CAMERA (row H / 2)
LEFT, RIGHT, ROW = 23, 40, 24


def _write(tmp_path, builder: GltfBuilder, name="model.glb"):
    path = tmp_path / name
    path.write_bytes(builder.glb())
    return path


def _unlit_scene(path):
    scene = mesh_scene(path)
    scene.light = None  # a pixel shows the surface's own color
    return scene


def _cut_out_quad(tmp_path, mode="MASK", name="model.glb", **extra):
    """A red wall behind a quad whose texture is cut out (alpha 0, blue) on its left half, green on its right."""
    b = GltfBuilder()
    b.quad(BACK, material=b.material(pbrMetallicRoughness={"baseColorFactor": [1, 0, 0, 1]}))
    texels = np.zeros((8, 8, 4), np.uint8)
    texels[:, :4] = (0, 0, 255, 0)
    texels[:, 4:] = (0, 255, 0, 255)
    material = {"pbrMetallicRoughness": {"baseColorTexture": {"index": b.texture(texels)}}, "alphaMode": mode, **extra}
    b.quad(FRONT, material=b.material(**material))
    return _write(tmp_path, b, name)


def test_the_first_camera_is_the_scenes_and_the_others_are_viewpoints(tmp_path):
    b = GltfBuilder()
    b.quad(FRONT, material=b.material())
    b.camera("Front", (0, 0, 5), yfov_degrees=30)
    b.camera("Side", (6, 0, 0), rotation=quaternion((0, 1, 0), 90), yfov_degrees=45)  # its -z turned to -x
    scene = mesh_scene(_write(tmp_path, b))
    assert scene.camera.eye == pytest.approx((0, 0, 5)) and scene.camera.fov == pytest.approx(30)
    # look_at where the view first meets the model: the quad at z = 0 (what the depth mapping focuses on)
    assert scene.camera.look_at == pytest.approx((0, 0, 0), abs=1e-5)
    assert list(scene.viewpoints) == ["Side"]
    side = scene.viewpoints["Side"]
    assert side.eye == pytest.approx((6, 0, 0)) and side.fov == pytest.approx(45)
    np.testing.assert_allclose(
        np.subtract(side.look_at, side.eye) / np.linalg.norm(np.subtract(side.look_at, side.eye)), [-1, 0, 0], atol=1e-9
    )


def test_a_directional_light_is_the_scenes_light_and_a_point_light_shines_towards_the_model(tmp_path):
    b = GltfBuilder()
    b.quad(FRONT, material=b.material())
    b.light("Sun", "directional", rotation=quaternion((1, 0, 0), -90))  # its -z turned straight down
    scene = mesh_scene(_write(tmp_path, b))
    np.testing.assert_allclose(scene.light.direction, [0, -1, 0], atol=1e-9)
    b = GltfBuilder()
    b.quad(FRONT, material=b.material())
    b.light("Bulb", "point", translation=(0, 0, 3))
    scene = mesh_scene(_write(tmp_path, b, "point.glb"))
    np.testing.assert_allclose(scene.light.direction, [0, 0, -1], atol=1e-9)  # from the bulb to the model's centre


@pytest.mark.parametrize("spp", [1, 2])
def test_a_cut_out_shows_what_is_behind_it(tmp_path, spp):
    scene = _unlit_scene(_cut_out_quad(tmp_path, alphaCutoff=0.5))
    assert scene.geometry()[0].masked
    image = paint(scene, CAMERA, W, H, PaintParams(iterations=3, spp=spp, lambda_p=2.0), threads=1).image
    np.testing.assert_allclose(image[ROW, LEFT], [1, 0, 0], atol=1e-6)  # the red wall, through the cut
    np.testing.assert_allclose(image[ROW, RIGHT], [0, 1, 0], atol=2e-4)  # the quad's green half


def test_an_opaque_material_ignores_its_textures_alpha_and_blend_is_a_mask_at_one_half(tmp_path):
    opaque = _unlit_scene(_cut_out_quad(tmp_path, mode="OPAQUE"))
    assert not opaque.geometry()[0].masked  # nothing to pass through: no alpha pass at all
    image = paint(opaque, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
    np.testing.assert_allclose(image[ROW, LEFT], [0, 0, 1], atol=2e-4)  # the cut-out's own color
    blend = _unlit_scene(_cut_out_quad(tmp_path, mode="BLEND", name="blend.glb"))
    image = paint(blend, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
    np.testing.assert_allclose(image[ROW, LEFT], [1, 0, 0], atol=1e-6)
    # a whole BLEND surface below one half of coverage is not drawn; above, it is opaque
    for coverage, drawn in ((0.4, False), (0.6, True)):
        b = GltfBuilder()
        b.quad(BACK, material=b.material(pbrMetallicRoughness={"baseColorFactor": [1, 0, 0, 1]}))
        b.quad(
            FRONT, material=b.material(pbrMetallicRoughness={"baseColorFactor": [0, 1, 0, coverage]}, alphaMode="BLEND")
        )
        scene = _unlit_scene(_write(tmp_path, b, f"glass{coverage}.glb"))
        image = paint(scene, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
        np.testing.assert_allclose(image[ROW, LEFT], [0, 1, 0] if drawn else [1, 0, 0], atol=1e-6)


def test_base_color_factor_times_texture_times_vertex_colors(tmp_path):
    b = GltfBuilder()
    texels = np.full((4, 4, 4), (255, 128, 255, 255), np.uint8)
    material = b.material(
        pbrMetallicRoughness={"baseColorTexture": {"index": b.texture(texels)}, "baseColorFactor": [0.5, 1, 1, 1]}
    )
    b.quad(FRONT, material=material, colors=np.full((4, 3), (1.0, 1.0, 0.25), np.float32))
    scene = _unlit_scene(_write(tmp_path, b))
    image = paint(scene, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
    # factors and vertex colors are linear in glTF: encoded to display values, then multiplied
    expected = gltf.display([0.5, 1, 1]) * [1, 128 / 255, 1] * gltf.display([1, 1, 0.25])
    np.testing.assert_allclose(image[ROW, LEFT], expected, atol=2e-4)


def test_emission_adds_to_the_lit_color_from_its_factor_and_texture(tmp_path):
    b = GltfBuilder()
    b.quad(
        BACK, material=b.material(pbrMetallicRoughness={"baseColorFactor": [0, 0, 0, 1]}, emissiveFactor=[1, 0.5, 0])
    )
    glow = np.full((2, 2, 4), (0, 255, 128, 255), np.uint8)
    b.quad(
        FRONT,
        material=b.material(
            pbrMetallicRoughness={"baseColorFactor": [0, 0, 0, 1]},
            emissiveFactor=[1, 1, 1],
            emissiveTexture={"index": b.texture(glow)},
        ),
    )
    scene = mesh_scene(_write(tmp_path, b))  # lit: black surfaces show only their emission
    image = paint(scene, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
    np.testing.assert_allclose(image[ROW, LEFT], [0, 1, 128 / 255], atol=2e-4)
    np.testing.assert_allclose(image[4, 2], gltf.display([1, 0.5, 0]), atol=1e-6)  # the wall, beside the quad


def test_an_unlit_material_shows_its_color_whatever_the_light(tmp_path):
    b = GltfBuilder()
    b.quad(BACK, material=b.material(pbrMetallicRoughness={"baseColorFactor": [0.2, 0.4, 0.6, 1]}))
    b.quad(
        FRONT,
        material=b.material(
            pbrMetallicRoughness={"baseColorFactor": [0.2, 0.4, 0.6, 1]}, extensions={"KHR_materials_unlit": {}}
        ),
    )
    b.light("Grazing", "directional", rotation=quaternion((0, 1, 0), 89))  # nearly along the quads
    scene = mesh_scene(_write(tmp_path, b))
    image = paint(scene, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
    np.testing.assert_allclose(image[ROW, LEFT], gltf.display([0.2, 0.4, 0.6]), atol=1e-6)
    assert np.all(image[4, 2] < 0.5 * gltf.display([0.2, 0.4, 0.6]))  # the same color, lit, is dark


def test_a_texture_transform_moves_the_texture(tmp_path):
    texels = np.zeros((1, 4, 4), np.uint8)
    texels[:, :2] = (255, 0, 0, 255)
    texels[:, 2:] = (0, 0, 255, 255)
    for offset, left in ((None, [1, 0, 0]), ([0.5, 0], [0, 0, 1])):
        b = GltfBuilder()
        reference = {"index": b.texture(texels)}
        if offset is not None:
            reference["extensions"] = {"KHR_texture_transform": {"offset": offset}}
        b.quad(FRONT, material=b.material(pbrMetallicRoughness={"baseColorTexture": reference}))
        scene = _unlit_scene(_write(tmp_path, b, f"t{offset}.glb"))
        image = paint(scene, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
        np.testing.assert_allclose(image[ROW, LEFT], left, atol=2e-4)
    # rotation and scale as the extension defines them: T * R * S on (u, v)
    m = gltf.uv_transform({"offset": [0.1, 0.2], "rotation": math.pi / 2, "scale": [2, 3]})
    np.testing.assert_allclose(m @ [1, 1, 1], [0.1 + 3, 0.2 - 2, 1], atol=1e-12)


def test_obj_map_d_cuts_out_and_d_hides(tmp_path):
    Image.fromarray(np.full((4, 4, 3), (0, 255, 0), np.uint8)).save(tmp_path / "color.png")
    mask = np.full((4, 4), 255, np.uint8)
    mask[:, :2] = 0
    Image.fromarray(mask).save(tmp_path / "mask.png")
    (tmp_path / "m.mtl").write_text("newmtl cut\nKd 1 1 1\nmap_Kd color.png\nmap_d mask.png\nnewmtl wall\nKd 1 0 0\n")
    faces = "usemtl wall\nf 5/1 6/2 7/3\nf 5/1 7/3 8/4\nusemtl cut\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
    vertices = "".join(f"v {x} {y} {z}\n" for x, y, z in FRONT + BACK)
    (tmp_path / "m.obj").write_text("mtllib m.mtl\n" + vertices + "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n" + faces)
    scene = _unlit_scene(tmp_path / "m.obj")
    image = paint(scene, CAMERA, W, H, PaintParams(iterations=1), threads=1).image
    np.testing.assert_allclose(image[ROW, LEFT], [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(image[ROW, RIGHT], [0, 1, 0], atol=2e-4)
    (tmp_path / "m.mtl").write_text("newmtl cut\nKd 0 1 0\nd 0.3\nnewmtl wall\nKd 1 0 0\n")
    assert len(load_model(tmp_path / "m.obj").parts) == 1  # dissolved below one half: not drawn


def test_the_sandboxs_arrays_carry_materials_cameras_and_lights(tmp_path):
    from rcp_server.scene.unpack import Limits, write_parts
    from rcp_server.scene.untrusted import parts_from_arrays

    b = GltfBuilder()
    b.quad(BACK, material=b.material(emissiveFactor=[1, 0.5, 0], extensions={"KHR_materials_unlit": {}}))
    b.camera("Front", (0, 0, 5))
    b.light("Sun", "directional", rotation=quaternion((1, 0, 0), -90))
    path = _cut_out_quad(tmp_path, alphaCutoff=0.25)
    data = b.glb()
    (tmp_path / "other.glb").write_bytes(data)
    for source in (path, tmp_path / "other.glb"):
        model = load_model(source)
        write_parts(tmp_path / "parts.npz", model)
        back = parts_from_arrays(tmp_path / "parts.npz", Limits())
        assert back.viewpoints == model.viewpoints and back.lights == model.lights
        for a, b_ in zip(model.parts, back.parts, strict=True):
            assert (a.material.emission, a.material.unlit, a.material.alpha_cutoff) == (
                b_.material.emission,
                b_.material.unlit,
                b_.material.alpha_cutoff,
            )
            if a.texture is not None:
                np.testing.assert_array_equal(a.texture, b_.texture)
            if a.material.alpha_texture is not None:
                np.testing.assert_array_equal(a.material.alpha_texture, b_.material.alpha_texture)


def test_the_geometry_keeps_a_models_textures_without_copying_them(tmp_path):
    scene = _unlit_scene(_cut_out_quad(tmp_path))
    geometry, _ = scene.geometry()
    textured = [obj.part for obj in scene.objects if obj.part.texture is not None]
    assert textured and all(np.shares_memory(part.texture, geometry.texels) for part in textured)
    assert geometry.texels.dtype == np.uint8 and geometry.texels.shape[1] == 3
    # the cut-out's coverage is kept apart, for the one texture whose material lets rays through
    assert geometry.alpha_texels.size == 8 * 8 and (geometry.texture_alpha_offset >= 0).sum() == 1


def test_a_scene_without_cut_outs_never_enters_the_alpha_pass(tmp_path, monkeypatch):
    """The pass is skipped unless a scene has cut-outs: a tile's compiled iteration reads it from its
    ``Trace``, and the pass of what pixel centres see (outlines, picks, shared eyes) never calls it."""
    from rcp_server.painting import frame, picking, seen

    def refuse(*args):
        raise AssertionError("the alpha pass ran for a scene without cut-outs")

    monkeypatch.setattr(seen, "pass_masked", refuse)
    scene = _unlit_scene(_cut_out_quad(tmp_path, mode="OPAQUE"))
    assert not frame.Frame.of(scene, 0.0, CAMERA, PaintParams()).trace.masked
    for spp in (1, 2):
        paint(scene, CAMERA, W, H, PaintParams(iterations=2, spp=spp, lambda_p=2.0), threads=1)
    picking.pick(scene, 0.0, CAMERA, W, H, W // 2, H // 2)
    masked = _unlit_scene(_cut_out_quad(tmp_path, mode="MASK", name="masked.glb"))
    assert frame.Frame.of(masked, 0.0, CAMERA, PaintParams()).trace.masked
    with pytest.raises(AssertionError, match="alpha pass ran"):  # the same patch does see a scene with them
        picking.pick(masked, 0.0, CAMERA, W, H, W // 2, H // 2)


def test_a_malformed_gltf_json_yields_what_it_can_and_never_raises():
    document = {
        "nodes": [
            {"children": 5, "camera": 0, "extensions": {"KHR_lights_punctual": {"light": 1}}},
            {"children": [0, "x"]},
        ],
        "cameras": [{"type": "perspective", "perspective": 3}],
        "extensions": {"KHR_lights_punctual": {"lights": [5, {"type": "spot"}]}},
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"extensions": 4}}, "alphaCutoff": "x"}, 7],
        "scenes": [{"nodes": [1]}],
    }
    found = gltf.extras(document)
    assert found.viewpoints == [] and [light.kind for light in found.lights] == ["spot"]
    assert len(found.materials) == 2 and found.materials[0].alpha_cutoff == 0.5


def test_cameras_that_cannot_frame_the_scene_are_skipped_and_the_scene_falls_back_on_its_framed_view(tmp_path, caplog):
    """A camera far away, under a parent scaled huge, or whose up lies along its view is left out in one line
    each; with none left the scene's camera is the framed one (as for a file with no camera)."""
    caplog.set_level("INFO", "rcp")
    b = GltfBuilder()
    b.quad(FRONT, material=b.material())
    b.camera("Far", (5e9, 0, 5))
    b.camera("Inside", (1, 0, 5))
    b.gltf["nodes"].append({"scale": [1e12, 1e12, 1e12], "children": [len(b.gltf["nodes"]) - 1]})
    b.gltf["scenes"][0]["nodes"] = [0, 1, len(b.gltf["nodes"]) - 1]  # the camera "Inside" under the huge parent
    b.camera("Edge", (0, 0, 5))
    b.gltf["nodes"][-1] = {"camera": 2, "matrix": [1, 0, 0, 0, 0, 0, 1, 0, 0, 0, -1, 0, 0, 0, 5, 1]}  # up = -view
    scene = mesh_scene(_write(tmp_path, b))
    plain = mesh_scene(_write(tmp_path, _with_quad_only(), "plain.glb"))
    assert scene.camera == plain.camera and scene.viewpoints == {}
    notes = [m for m in caplog.messages if " skipped: " in m]
    assert [n.split(" skipped: ")[0] for n in notes] == [
        "model.glb: camera 'Far'",
        "model.glb: camera 'Inside'",
        "model.glb: camera 'Edge'",
    ]
    assert "within +-" in notes[0] and "within +-" in notes[1] and "up is parallel to the view direction" in notes[2]


def _with_quad_only() -> GltfBuilder:
    b = GltfBuilder()
    b.quad(FRONT, material=b.material())
    return b


def test_a_files_cameras_and_lights_are_bounded(tmp_path):
    """A thousand camera nodes (and as many lights) in a file: the first 256 of each are kept."""
    b = GltfBuilder()
    b.quad(FRONT, material=b.material())
    b.camera("c", (0, 0, 5))
    b.light("l", "point", (0, 0, 3))
    camera, light = b.gltf["nodes"][-2], b.gltf["nodes"][-1]
    b.gltf["nodes"] += [dict(camera, translation=[0, 0, 5 + k * 1e-3]) for k in range(1000)]
    b.gltf["nodes"] += [dict(light) for _ in range(1000)]
    b.gltf["scenes"][0]["nodes"] = list(range(len(b.gltf["nodes"])))
    found = gltf.extras(b.gltf)
    assert len(found.viewpoints) == gltf.MAX_VIEWPOINTS == 256 and len(found.lights) == gltf.MAX_LIGHTS == 256
    scene = mesh_scene(_write(tmp_path, b))
    assert len(scene.viewpoints) == 255  # the first is the scene's camera
