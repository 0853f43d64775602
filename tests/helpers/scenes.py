"""Tiny scenes built in code, shared by the tests. Nothing here reads files outside the repository.

The standard camera sits at the origin looking down -z, so ``r = +x``, ``u = +y``, ``f = -z`` and a
point's view depth is ``-z``. A "facing plane" is a grid turned to face the camera at a given depth.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from rcp_server.camera.camera import Camera
from rcp_server.engine.paintstate import PaintState
from rcp_server.scene.meshes import Material, Part, primitive
from rcp_server.scene.scene import Environment, Scene, SceneObject
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


def inked_scene(outline: float) -> Scene:
    """A box turned to show two faces, in front of a wall at depth 8; the box's material draws outlines."""
    ink = Material(name="inked", outline=outline)
    part = replace(primitive("box", extents=(1.6, 1.6, 1.6)), material=ink)
    turn = np.array([[0.8, 0, 0.6, 0], [0, 1, 0, 0], [-0.6, 0, 0.8, 0], [0, 0, 0, 1]], float)
    box = SceneObject("box#0", part, [(translate(0.0, -0.8, -4.0) @ turn, part)], label="box")
    return make_scene([box, facing_plane(8.0, color=(0.9, 0.9, 0.9), name="wall")])


# ---- what the painting tests share: the image size they paint, and hit points read back from a state ----

W, H = 48, 32


def hit_points(state: PaintState, camera: Camera = CAMERA) -> np.ndarray:
    """World hit points from a state that recorded depth and direction (spp = 1): (n, 3) float64."""
    r, u, f = camera.basis()
    direction = state.direction.astype(np.float64)
    along = state.depth.astype(np.float64) / (direction @ f)
    return np.asarray(camera.eye) + along[:, None] * direction
