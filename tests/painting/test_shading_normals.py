"""Shading normals (meshes.corner_normals): flat faces stay flat, round surfaces stay round.

A crease is decided per pair of faces around a vertex: a corner's normal is the angle-weighted mean of
the faces within the crease angle of its own face; with no crease that is trimesh's ``vertex_normals``.
"""

import math

import numpy as np
import trimesh
from helpers.scenes import CAMERA, make_scene, translate

from rcp_server.painting.loop import paint
from rcp_server.scene.meshes import CREASE_COS, DEFAULT_ALBEDO, corner_normals, grid, primitive
from rcp_server.scene.scene import Light, SceneObject, Waves
from rcp_server.settings.params import PaintParams

SLAB = (3.0, 4.0, 1.0)  # 3 wide, 4 tall, 1 deep: the box


def _face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return trimesh.Trimesh(vertices, faces, process=False).face_normals


def _trimesh_corner_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """trimesh's vertex normals of exactly these faces, at each corner: (F, 3, 3)."""
    return trimesh.Trimesh(vertices, faces, process=False).vertex_normals[faces]


def _reference(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """corner_normals written as its definition, one corner at a time (loops: a reference, not a renderer)."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    face_n, angles = mesh.face_normals, mesh.face_angles
    out = np.zeros((len(faces), 3, 3))
    for f in range(len(faces)):
        for c in range(3):
            around, at = np.nonzero(faces == faces[f, c])
            near = face_n[around] @ face_n[f] >= CREASE_COS
            summed = (angles[around, at][near, None] * face_n[around][near]).sum(axis=0)
            out[f, c] = summed / np.linalg.norm(summed)
    return out


def _lumpy_sphere() -> tuple[np.ndarray, np.ndarray]:
    """An icosphere with seeded random radii: creases at some vertices, none at others."""
    sphere = primitive("sphere", subdivisions=2)
    radius = np.random.default_rng(7).uniform(0.75, 1.25, len(sphere.vertices))
    return sphere.vertices * radius[:, None], sphere.faces


def _sea(time: float) -> tuple[np.ndarray, np.ndarray]:
    """A wave-deformed grid like scenes/sea.toml's, at ``time`` seconds."""
    vertices, faces, _ = grid((40.0, 40.0), (60, 60))
    for wave in (
        Waves(0.5, 16.0, (1.0, 0.35), 3.2),
        Waves(0.3, 9.0, (-0.4, 1.0), 2.4),
        Waves(0.14, 5.2, (0.8, -0.6), 1.9),
    ):
        vertices[:, 1] += wave.height(vertices[:, 0], vertices[:, 2], time)
    return vertices, faces


# ---- the definition ----


def test_corner_normals_follow_their_definition_at_every_corner():
    for vertices, faces in (
        _lumpy_sphere(),
        (primitive("box", extents=SLAB).vertices, primitive("box", extents=SLAB).faces),
        (primitive("cylinder", sections=12).vertices, primitive("cylinder", sections=12).faces),
        (primitive("cone", sections=16).vertices, primitive("cone", sections=16).faces),
    ):
        np.testing.assert_allclose(corner_normals(vertices, faces), _reference(vertices, faces), atol=1e-12)


def test_where_no_crease_applies_the_normals_are_trimesh_vertex_normals():
    for subdivisions in (1, 2, 3):
        sphere = primitive("sphere", subdivisions=subdivisions)
        expected = _trimesh_corner_normals(sphere.vertices, sphere.faces)
        np.testing.assert_allclose(corner_normals(sphere.vertices, sphere.faces), expected, atol=1e-12)
    for time in (0.0, 2.5):
        vertices, faces = _sea(time)
        np.testing.assert_allclose(
            corner_normals(vertices, faces), _trimesh_corner_normals(vertices, faces), atol=1e-12
        )


def test_a_tessellated_sphere_stays_smooth():
    for subdivisions in (1, 2, 3):
        sphere = primitive("sphere", subdivisions=subdivisions, radius=2.0)
        n = corner_normals(sphere.vertices, sphere.faces)
        # one normal per vertex, whichever face it is read from: no facets
        per_vertex = np.zeros((len(sphere.vertices), 3))
        per_vertex[sphere.faces.ravel()] = n.reshape(-1, 3)
        np.testing.assert_allclose(n, per_vertex[sphere.faces], atol=1e-12)
        # and that normal points out of the sphere, to within a few thousandths at the finest
        radial = sphere.vertices[sphere.faces] / 2.0
        assert np.einsum("fck,fck->fc", n, radial).min() > 1.0 - 0.02 / 4**subdivisions


# ---- flat where faces meet at a crease ----


def test_each_face_of_a_cube_and_a_slab_keeps_its_face_normal():
    for extents in ((1.0, 1.0, 1.0), SLAB):
        box = primitive("box", extents=extents)
        face_n = _face_normals(box.vertices, box.faces)
        np.testing.assert_allclose(
            corner_normals(box.vertices, box.faces), np.repeat(face_n[:, None], 3, axis=1), atol=1e-15
        )


def test_a_cylinder_is_flat_at_its_caps_and_smooth_around_its_side():
    cylinder = primitive("cylinder", radius=0.5, height=1.0, sections=24)
    n = corner_normals(cylinder.vertices, cylinder.faces)
    face_n = _face_normals(cylinder.vertices, cylinder.faces)
    cap = np.abs(face_n[:, 1]) > 0.5
    assert cap.any() and (~cap).any()
    np.testing.assert_allclose(n[cap], np.repeat(face_n[cap, None], 3, axis=1), atol=1e-15)
    # each side corner points straight out from the axis: the same normal on every side face at a vertex
    out = cylinder.vertices[cylinder.faces[~cap]] * [1.0, 0.0, 1.0]
    np.testing.assert_allclose(n[~cap], out / np.linalg.norm(out, axis=2, keepdims=True), atol=1e-12)
    # which is trimesh's smooth normal of the side alone
    side = cylinder.faces[~cap]
    np.testing.assert_allclose(n[~cap], _trimesh_corner_normals(cylinder.vertices, side), atol=1e-12)


def test_the_crease_angle_keeps_the_shipped_round_things_round_and_the_roofs_flat():
    # an octagonal trunk (45 degrees between sides) is round; a four-sided pyramid roof (52) is flat
    trunk = primitive("cylinder", radius=0.16, height=2.0, sections=8)
    face_n = _face_normals(trunk.vertices, trunk.faces)
    side = np.abs(face_n[:, 1]) < 0.5
    n = corner_normals(trunk.vertices, trunk.faces)
    np.testing.assert_allclose(n[side], _trimesh_corner_normals(trunk.vertices, trunk.faces[side]), atol=1e-12)
    roof = primitive("cone", radius=2.35, height=1.3, sections=4)
    face_n = _face_normals(roof.vertices, roof.faces)
    np.testing.assert_allclose(
        corner_normals(roof.vertices, roof.faces), np.repeat(face_n[:, None], 3, axis=1), atol=1e-15
    )


def test_a_degenerate_face_adds_nothing_to_its_neighbours():
    sphere = primitive("sphere", subdivisions=2)
    a, b, _ = sphere.faces[0]
    faces = np.concatenate([sphere.faces, [[a, b, b]]])  # zero area: no normal, and its angles are NaN
    n = corner_normals(sphere.vertices, faces)
    assert np.all(np.isfinite(n))
    np.testing.assert_allclose(n[:-1], corner_normals(sphere.vertices, sphere.faces), atol=1e-12)


# ---- through the engine: a slab under a directional light ----


def _slab_painting():
    """A lit slab turned to show its front, right side and top; painted plainly (lambda_p 0), one iteration.

    Returns the painted state (128 x 96), the slab's six distinct world face normals (6, 3), the light
    and the albedo.
    """
    slab = primitive("box", extents=SLAB)
    turn = trimesh.transformations.rotation_matrix(math.radians(-40.0), [0, 1, 0])
    tilt = trimesh.transformations.rotation_matrix(math.radians(30.0), [1, 0, 0])
    world = translate(0.0, -0.3, -5.5) @ tilt @ turn @ translate(y=-SLAB[1] / 2)
    tint = (0.9, 0.7, 0.5)
    part = slab.tinted(tint)  # over the primitives' default grey
    light = Light(tuple(np.array([-0.5, -0.7, -0.6]) / np.linalg.norm([-0.5, -0.7, -0.6])), 0.25)
    scene = make_scene([SceneObject("slab", part, [(world, part)])], light=light)
    state = paint(scene, CAMERA, 128, 96, PaintParams(mapping="normal", iterations=1, lambda_p=0.0)).state
    face_n = np.unique(np.round(_face_normals(slab.vertices, slab.faces), 9), axis=0) @ world[:3, :3].T
    return state, face_n, light, np.float32(DEFAULT_ALBEDO) * np.float32(tint)


def _face_seen(state, face_n: np.ndarray) -> np.ndarray:
    """Which of the slab's faces each pixel sees: (n,) index into face_n, -1 where the ray misses.

    A bent shading normal still lies nearest its own face's normal (a crease bends it by less than 45
    degrees), so this names the face even where the shading is wrong."""
    hit = np.any(state.normal != 0.0, axis=1)
    return np.where(hit, np.argmax(state.normal @ face_n.T, axis=1), -1)


def test_the_normal_recorded_for_each_face_of_a_slab_is_its_face_normal():
    state, face_n, _, _ = _slab_painting()
    seen = _face_seen(state, face_n)
    np.testing.assert_allclose(state.normal[seen >= 0], face_n[seen[seen >= 0]], atol=1e-6)
    # three faces in view (front, side and top), each over many pixels
    faces, pixels = np.unique(seen[seen >= 0], return_counts=True)
    assert len(faces) == 3 and pixels.min() > 150


def test_a_slab_under_a_light_is_lit_evenly_across_each_face():
    state, face_n, light, albedo = _slab_painting()
    h, w = 96, 128
    seen = _face_seen(state, face_n).reshape(h, w)
    # away from its edges: pixels whose 3 x 3 neighbourhood sees the same face
    padded = np.pad(seen, 1, constant_values=-2)
    inner = seen >= 0
    for dy in range(3):
        for dx in range(3):
            inner &= padded[dy : dy + h, dx : dx + w] == seen
    color = state.color.reshape(h, w, 3)
    faces = np.unique(seen[seen >= 0])
    assert len(faces) == 3
    for face in faces:
        pixels = color[inner & (seen == face)]
        lit = max(0.0, float(face_n[face] @ -np.asarray(light.direction)))
        expected = albedo * (light.ambient + (1 - light.ambient) * lit)
        assert len(pixels) > 50
        np.testing.assert_allclose(pixels, np.broadcast_to(expected, pixels.shape), atol=1 / 255)
