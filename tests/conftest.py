"""Tiny scenes built in code, shared by the tests. Nothing here reads files outside the repository.

The standard camera sits at the origin looking down -z, so ``r = +x``, ``u = +y``, ``f = -z`` and a
point's view depth is ``-z``. A "facing plane" is a grid turned to face the camera at a given depth.
"""

from __future__ import annotations

import numpy as np
import pytest

from rcp_server.camera.camera import Camera
from rcp_server.scene.meshes import Part, primitive
from rcp_server.scene.scene import Environment, Light, Scene, SceneObject
from rcp_server.settings.mappings import register_mapping

SPINNING_BOX = """
title = "tiny"
[camera]
eye = [0, 1, 4]
look_at = [0, 0.5, 0]
[environment]
color = [0.2, 0.5, 0.9]
[light]
direction = [-0.3, -1, -0.4]
[[objects]]
primitive = { type = "box", extents = [1, 1, 1] }
color = [0.9, 0.2, 0.1]
spin = { degrees_per_second = 90 }
"""
"""A scene file: a lit red box that spins, under a blue sky (for the command line, videos and animation)."""

CAMERA = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), fov=60.0)
SKY = (0.2, 0.35, 0.6)

# grid faces +y in the xz plane; a quarter turn about +x makes it face +z (towards the standard camera)
FACE_PLUS_Z = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def translate(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def facing_plane(
    depth: float,
    size=(16.0, 16.0),
    divisions=(4, 4),
    color=(1.0, 1.0, 1.0),
    center=(0.0, 0.0),
    colors_of=None,
    texture=None,
    uv_repeat=(1.0, 1.0),
    name="plane",
) -> SceneObject:
    """A plane at view depth ``depth`` facing the standard camera.

    ``colors_of(points (..., 3) world) -> (..., 3)`` gives per-corner albedo from world position.
    """
    part = primitive("grid", size=size, divisions=divisions, uv_repeat=uv_repeat)
    world = translate(center[0], center[1], -depth) @ FACE_PLUS_Z
    corners = part.vertices[part.faces] @ world[:3, :3].T + world[:3, 3]
    colors = (
        np.asarray(colors_of(corners), np.float32)
        if colors_of is not None
        else np.broadcast_to(np.float32(color), corners.shape).copy()
    )
    part = Part(part.vertices, part.faces, colors.astype(np.float32), part.corner_uv, texture)
    return SceneObject(name, part, [(world, part)])


def sphere(center=(0.0, 0.0, -4.0), radius=1.0, subdivisions=3, color=(1.0, 1.0, 1.0), name="sphere"):
    part = primitive("sphere", subdivisions=subdivisions, radius=radius).tinted(color)
    return SceneObject(name, part, [(translate(*center), part)])


def noise_texture(seed: int, size: int = 64) -> np.ndarray:
    """A texture of random texels, ``size x size`` RGB float32: every lookup lands on a different color."""
    return np.random.default_rng(seed).uniform(0, 1, (size, size, 3)).astype(np.float32)


def wavy_sky() -> Environment:
    """A 64x32 panorama whose color changes with longitude and latitude alike (silhouettes show against it)."""
    u, v = np.meshgrid(np.linspace(0, 1, 64), np.linspace(0, 1, 32))
    return Environment(np.stack([u, v, 0.5 + 0.5 * np.sin(12 * u)], axis=2).astype(np.float32))


def make_scene(objects=(), camera=CAMERA, sky=SKY, light=None, z_max=None, environment=None) -> Scene:
    env = environment if environment is not None else Environment.constant(sky)
    return Scene("test", "test", camera, env, light, list(objects), z_max=z_max)


def gradient(points: np.ndarray) -> np.ndarray:
    """An albedo linear in world x and y, inside [0.1, 0.9] on a 16x16 plane: (..., 3)."""
    x, y = points[..., 0], points[..., 1]
    return np.stack([0.5 + 0.05 * x, 0.5 + 0.05 * y, 0.3 + 0.0 * x], axis=-1)


# a mapping that moves nothing but reads (so records) every channel: used as the eye mapping with
# lambda_e != 0 to read back the depth, normal and direction a painting recorded
@register_mapping("test-probe", reads={"depth", "normal", "direction"})
def _probe(data):
    return np.zeros((len(data.color), 3))


@pytest.fixture(scope="session", autouse=True)
def _own_data_folder(tmp_path_factory):
    """``RCP_DATA`` in a temporary folder for the whole session: no test touches the user's data folder (servers
    started by tests get one of their own besides: ``bench.harness``)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("RCP_DATA", str(tmp_path_factory.mktemp("rcp-data")))
        yield


@pytest.fixture(scope="session")
def gradient_scene() -> Scene:
    """An unlit plane at depth 4 whose albedo is linear in x and y; it fills the standard view."""
    return make_scene([facing_plane(4.0, colors_of=gradient)])


@pytest.fixture(scope="session")
def busy_scene() -> Scene:
    """Lit, textured and colored objects at several depths in front of a gradient sky: every mapping moves."""
    rng = np.random.default_rng(0)
    texture = rng.uniform(0, 1, (8, 8, 3)).astype(np.float32)
    sky = np.stack([*np.meshgrid(np.linspace(0, 1, 32), np.linspace(0, 1, 16)), np.full((16, 32), 0.3)], axis=2).astype(
        np.float32
    )
    objects = [
        facing_plane(9.0, size=(10.0, 6.0), divisions=(3, 2), texture=texture, center=(0.0, -2.0)),
        sphere((-1.2, 0.3, -4.5), 1.0, 2, (0.9, 0.2, 0.1), "red"),
        sphere((1.5, -0.4, -6.0), 1.3, 2, (0.1, 0.8, 0.3), "green"),
        sphere((0.4, 1.2, -3.0), 0.4, 1, (0.2, 0.3, 0.95), "blue"),
    ]
    light = Light(tuple(np.array([-0.3, -1.0, -0.4]) / np.linalg.norm([-0.3, -1.0, -0.4])), 0.3)
    return make_scene(objects, light=light, environment=Environment(sky))
