"""Mesh files and primitives become Parts; broken input is repaired with a warning or refused by name."""

import logging

import numpy as np
import pytest
import trimesh
from PIL import Image

from rcp_server.scene.meshes import (
    DEFAULT_ALBEDO,
    MeshError,
    Part,
    corner_normals,
    load_mesh_file,
    primitive,
    repaired,
)


def _write(path, text):
    path.write_text(text)
    return path


QUAD_OBJ_VERTEX_COLORS = """\
v 0 0 0 1 0 0
v 1 0 0 0 1 0
v 0 1 0 0 0 1
v 1 1 0 1 1 0
f 1 2 3
f 2 4 3
"""


def test_obj_vertex_colors_become_corner_colors(tmp_path):
    parts = load_mesh_file(_write(tmp_path / "quad.obj", QUAD_OBJ_VERTEX_COLORS))
    assert len(parts) == 1
    part = parts[0]
    assert part.faces.shape == (2, 3) and part.texture is None
    # each corner carries its own vertex's color, wherever trimesh put the vertex
    corners = part.vertices[part.faces]
    expected = {(0, 0): (1, 0, 0), (1, 0): (0, 1, 0), (0, 1): (0, 0, 1), (1, 1): (1, 1, 0)}
    for f in range(2):
        for c in range(3):
            key = tuple(int(round(v)) for v in corners[f, c, :2])
            np.testing.assert_allclose(part.corner_colors[f, c], expected[key], atol=1e-6)


def test_ply_face_colors_and_stl_load(tmp_path):
    box = trimesh.creation.box(extents=(1, 2, 3))
    box.visual.face_colors = np.tile([[255, 0, 0, 255], [0, 0, 255, 255]], (6, 1))
    (tmp_path / "box.ply").write_bytes(box.export(file_type="ply"))
    (tmp_path / "box.stl").write_bytes(trimesh.creation.box(extents=(1, 2, 3)).export(file_type="stl"))
    ply = load_mesh_file(tmp_path / "box.ply")
    stl = load_mesh_file(tmp_path / "box.stl")
    for parts in (ply, stl):
        assert len(parts) == 1 and parts[0].faces.shape == (12, 3)
        tri = parts[0].vertices[parts[0].faces].reshape(-1, 3)
        np.testing.assert_allclose(tri.max(axis=0) - tri.min(axis=0), (1, 2, 3), atol=1e-6)
    colors = ply[0].corner_colors
    # every face is one flat color, half red and half blue
    assert np.all(colors == colors[:, :1])
    assert {tuple(c) for c in colors[:, 0]} == {(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)}
    np.testing.assert_allclose(stl[0].corner_colors, np.broadcast_to(np.float32(DEFAULT_ALBEDO), (12, 3, 3)))


@pytest.mark.parametrize(
    "name,content",
    [
        ("garbage.obj", b"\x00\xff\x13garbage\x00" * 40),
        ("garbage.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 999\nend_header\n\x01\x02"),
        ("garbage.glb", b"glTF\x02\x00\x00\x00garbage"),
        ("garbage.stl", b"solid x\nfacet normal 0 0\nendsolid"),
    ],
)
def test_unreadable_mesh_file_is_a_mesh_error_naming_the_file(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(MeshError) as info:
        load_mesh_file(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_missing_and_empty_mesh_files(tmp_path):
    with pytest.raises(MeshError, match="no such mesh file"):
        load_mesh_file(tmp_path / "nope.obj")
    with pytest.raises(MeshError, match="no triangles"):
        load_mesh_file(_write(tmp_path / "points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"))
    with pytest.raises(MeshError, match="no usable triangles"):
        load_mesh_file(_write(tmp_path / "line.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"))


def test_zero_area_faces_are_dropped_with_a_warning(tmp_path, caplog):
    path = _write(tmp_path / "deg.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n")
    with caplog.at_level(logging.WARNING, logger="rcp"):
        parts = load_mesh_file(path)
    assert parts[0].faces.shape == (1, 3)
    warnings = [r for r in caplog.records if r.name == "rcp" and r.levelno == logging.WARNING]
    assert len(warnings) == 1 and str(path) in warnings[0].getMessage()
    assert "dropped 1 of 2 faces" in warnings[0].getMessage()


@pytest.mark.parametrize("suffix", ["obj", "ply"])
def test_nan_vertices_are_repaired_with_a_warning(tmp_path, caplog, suffix):
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 1, 0], [2, 2, np.inf]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4], [0, 1, 4]])
    mesh = trimesh.Trimesh(vertices, faces, process=False, validate=False)
    path = tmp_path / f"nan.{suffix}"
    data = (
        trimesh.exchange.obj.export_obj(mesh)
        if suffix == "obj"
        else trimesh.exchange.ply.export_ply(mesh, encoding="ascii")
    )
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    assert "nan" in path.read_text().lower()
    with caplog.at_level(logging.WARNING, logger="rcp"):
        parts = load_mesh_file(path)
    assert len(parts) == 1
    tri = parts[0].vertices[parts[0].faces]
    assert np.all(np.isfinite(tri))
    np.testing.assert_allclose(
        tri.reshape(-1, 3)[np.lexsort(tri.reshape(-1, 3).T)],
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float),
        atol=0,
    )
    # the three faces that touched a non-finite vertex are gone, and the user is told so
    warnings = [r.getMessage() for r in caplog.records if r.name == "rcp" and r.levelno == logging.WARNING]
    assert any(str(path) in w for w in warnings), warnings


def test_repaired_counts_and_keeps_good_faces(caplog):
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0], [3, 0, 0]], float)
    faces = np.array([[0, 1, 2], [0, 3, 2], [0, 1, 4], [2, 1, 0]])
    colors = np.arange(4 * 9, dtype=np.float32).reshape(4, 3, 3)
    uv = np.zeros((4, 3, 2), np.float32)
    uv[3, 0, 0] = np.nan
    with caplog.at_level(logging.WARNING, logger="rcp"):
        part = repaired(Part(vertices, faces, colors, uv, np.zeros((1, 1, 3), np.float32)), "src")
    np.testing.assert_array_equal(part.faces, faces[[0, 3]])
    np.testing.assert_array_equal(part.corner_colors, colors[[0, 3]])
    assert np.all(np.isfinite(part.corner_uv))
    text = " ".join(r.getMessage() for r in caplog.records)
    assert "dropped 2 of 4 faces (1 with non-finite vertices, 1 with zero area)" in text
    assert "non-finite texture coordinates" in text


def test_obj_with_missing_texture_keeps_its_flat_color_and_warns(tmp_path, caplog):
    _write(tmp_path / "tex.mtl", "newmtl m\nKd 0.2 0.6 0.4\nmap_Kd missing.png\n")
    path = _write(
        tmp_path / "tex.obj",
        "mtllib tex.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\n",
    )
    with caplog.at_level(logging.WARNING, logger="rcp"):
        parts = load_mesh_file(path)
    assert parts[0].texture is None
    np.testing.assert_allclose(parts[0].corner_colors, np.broadcast_to([0.2, 0.6, 0.4], (1, 3, 3)), atol=1 / 255)
    assert any(str(path) in r.getMessage() and "texture" in r.getMessage() for r in caplog.records if r.name == "rcp")


def test_obj_with_texture_loads_uv_and_image(tmp_path):
    Image.fromarray(np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)).save(
        tmp_path / "t.png"
    )
    _write(tmp_path / "tex.mtl", "newmtl m\nKd 1 1 1\nmap_Kd t.png\n")
    path = _write(
        tmp_path / "tex.obj",
        "mtllib tex.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\n",
    )
    part = load_mesh_file(path)[0]
    assert part.texture is not None and part.texture.shape == (2, 2, 3) and part.texture.dtype == np.uint8
    np.testing.assert_array_equal(part.texture[0, 0], [255, 0, 0])  # 8-bit as the file holds it
    np.testing.assert_array_equal(part.texture[1, 1], [255, 255, 255])
    assert part.material.alpha_texture is None  # opaque: no coverage kept
    corners = part.vertices[part.faces[0]]
    # each corner's uv is its vertex's position (that is how the file pairs them)
    np.testing.assert_allclose(part.corner_uv[0], corners[:, :2], atol=1e-6)


def test_primitives_sit_on_the_ground_with_outward_normals():
    for kind in ("box", "cylinder", "cone"):
        part = primitive(kind)
        assert part.vertices[:, 1].min() == pytest.approx(0.0, abs=1e-12)
    sphere = primitive("sphere", subdivisions=2, radius=2.0)
    np.testing.assert_allclose(np.linalg.norm(sphere.vertices, axis=1), 2.0, rtol=1e-12)
    n = corner_normals(sphere.vertices, sphere.faces)
    np.testing.assert_allclose(np.einsum("fck,fck->fc", n, sphere.vertices[sphere.faces] / 2.0), 1.0, atol=1e-3)
    box = primitive("box", extents=(2, 2, 2))
    bn = corner_normals(box.vertices, box.faces)
    # crisp box: every corner keeps its face normal, one of the six axes
    assert np.all(np.isclose(np.abs(bn).max(axis=2), 1.0))
    grid = primitive("grid", size=(2, 4), divisions=(2, 3), uv_repeat=(1, 2))
    assert grid.faces.shape == (12, 3) and grid.corner_uv.shape == (12, 3, 2)
    assert grid.corner_uv[..., 1].max() == pytest.approx(2.0)
    with pytest.raises(MeshError, match="torus"):
        primitive("torus")


def test_a_file_of_many_meshes_shares_its_textures_and_skips_unusable_meshes(tmp_path, caplog):
    from PIL import Image

    from rcp_server.scene.scene import SceneObject, build_geometry

    material = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.new("RGB", (4, 4), (200, 30, 60)))
    quad_uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    scene = trimesh.Scene()
    for k in range(3):
        vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float) + [2.0 * k, 0, 0]
        if k == 2:
            vertices[:] = vertices[0]  # every face of this mesh has zero area
        visual = trimesh.visual.TextureVisuals(uv=quad_uv, material=material)
        scene.add_geometry(trimesh.Trimesh(vertices, [[0, 1, 2], [1, 3, 2]], visual=visual, process=False))
    path = tmp_path / "many.glb"
    path.write_bytes(scene.export(file_type="glb"))
    with caplog.at_level(logging.WARNING, logger="rcp"):
        parts = load_mesh_file(path)
    assert len(parts) == 2
    assert any("skipped 1 of 3 meshes" in r.getMessage() for r in caplog.records if r.name == "rcp")
    objects = [SceneObject(f"m{k}", p, [(np.eye(4), p)]) for k, p in enumerate(parts)]
    geometry = build_geometry(objects, 0.0)
    assert len(geometry.texture_width) == 1 and geometry.texels.shape == (16, 3)  # one image, not one per mesh
    np.testing.assert_array_equal(geometry.texels[0], [200, 30, 60])
