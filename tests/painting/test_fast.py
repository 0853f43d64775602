"""The ``fast`` setting against tracing every ray of every iteration (``fast=False``).

Bound: at least 99% of pixels within 2/255 of the exact painting, on scenes built to break the shortcuts
(textures, thin poles narrower than a pixel, silhouettes against a panorama), for every mapping, with
and without noise, at 1 and 4 samples. Where the eyes move, equal to the bit.
"""

from dataclasses import replace

import numpy as np
import pytest
from conftest import CAMERA, facing_plane, make_scene, noise_texture, sphere, translate, wavy_sky

from rcp_server.camera.camera import Camera, Region
from rcp_server.engine import kernels
from rcp_server.engine.kernels.embree import Hits
from rcp_server.engine.paintstate import PaintState
from rcp_server.painting.loop import paint, see, seen_grid
from rcp_server.painting.raytrace import Rays, assign_cameras, setup_tile, visible_faces
from rcp_server.scene.meshes import primitive
from rcp_server.scene.scene import Light, SceneObject
from rcp_server.settings.mappings import BUILT_IN
from rcp_server.settings.params import PaintParams

W, H = 128, 72
WITHIN = 2 / 255  # the bound of a pixel, in every channel ...
SHARE = 0.99  # ... for this share of the pixels


def _pole(x: float, depth: float, radius: float) -> SceneObject:
    part = primitive("cylinder", radius=radius, height=6.0, sections=6).tinted((0.95, 0.9, 0.2))
    return SceneObject("pole", part, [(translate(x, -2.5, -depth), part)])


def _box(x: float, y: float, depth: float, size: float, color) -> SceneObject:
    part = primitive("box", extents=(size, size, size)).tinted(color)
    world = translate(x, y, -depth) @ np.array(
        [[0.8, 0.0, 0.6, 0.0], [0.0, 1.0, 0.0, 0.0], [-0.6, 0.0, 0.8, 0.0], [0.0, 0.0, 0.0, 1.0]]
    )
    return SceneObject("box", part, [(world, part)])


@pytest.fixture(scope="module")
def hard_scene():
    """Everything the shortcuts could get wrong: a fine texture, poles thinner than a pixel (at this size a
    pixel is 0.08 units wide at depth 5), boxes and spheres with silhouettes against a panorama sky."""
    texture = noise_texture(7)
    objects = [
        facing_plane(14.0, size=(30.0, 8.0), divisions=(6, 2), texture=texture, center=(0.0, -3.0), uv_repeat=(4, 1)),
        sphere((-1.4, 0.4, -5.0), 1.0, 3, (0.9, 0.2, 0.1), "red"),
        sphere((2.2, 1.1, -7.0), 0.8, 2, (0.2, 0.3, 0.95), "blue"),
        _box(1.0, -1.6, 6.0, 1.2, (0.2, 0.8, 0.3)),
        _pole(0.3, 5.0, 0.02),  # half a pixel wide
        _pole(-2.6, 5.0, 0.06),  # one and a half pixels
        _pole(3.0, 9.0, 0.03),
    ]
    light = Light(tuple(np.array([-0.3, -1.0, -0.4]) / np.linalg.norm([-0.3, -1.0, -0.4])), 0.3)
    return make_scene(objects, light=light, environment=wavy_sky())


LAMBDA = {"color": 12.0, "depth": 3.0, "normal": 14.0, "cubist": 6.0}  # the smudge of a painting that looks painted


def _close_share(a: np.ndarray, b: np.ndarray) -> float:
    return float((np.abs(a - b).max(axis=-1) <= WITHIN + 1e-6).mean())


@pytest.mark.parametrize("noise", [0.0, 0.3])
@pytest.mark.parametrize("spp", [1, 4])
@pytest.mark.parametrize("mapping", BUILT_IN)
def test_fast_is_within_two_levels_of_exact_almost_everywhere(hard_scene, mapping, spp, noise):
    params = PaintParams(mapping=mapping, lambda_p=LAMBDA[mapping], spp=spp, noise=noise, seed=1, z0=6.0)
    exact = paint(hard_scene, CAMERA, W, H, replace(params, fast=False), keep_iterations=True)
    fast = paint(hard_scene, CAMERA, W, H, params, keep_iterations=True)
    np.testing.assert_array_equal(fast.iterations[0], exact.iterations[0])  # the plain render is never touched
    assert _close_share(fast.image, exact.image) >= SHARE
    assert np.abs(exact.image - exact.iterations[0]).max() > 0.2  # and the painting did move


@pytest.mark.parametrize("mapping", BUILT_IN)
def test_fast_is_within_two_levels_of_exact_on_the_busy_scene(busy_scene, mapping):
    params = PaintParams(mapping=mapping, lambda_p=LAMBDA[mapping], iterations=6)
    exact = paint(busy_scene, CAMERA, W, H, replace(params, fast=False)).image
    assert _close_share(paint(busy_scene, CAMERA, W, H, params).image, exact) >= SHARE


@pytest.mark.parametrize("mapping", BUILT_IN)
def test_where_eyes_move_fast_is_exact(hard_scene, mapping):
    params = PaintParams(
        mapping=mapping, eye_mapping=mapping, lambda_p=LAMBDA[mapping], lambda_e=0.05, spp=2, noise=0.2
    )
    exact = paint(hard_scene, CAMERA, W, H, replace(params, fast=False))
    fast = paint(hard_scene, CAMERA, W, H, params)
    for name in ("color", "depth", "normal", "direction"):
        a, b = getattr(exact.state, name), getattr(fast.state, name)
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_array_equal(b, a)


def test_fast_continuing_a_painting_stays_within_the_bound(hard_scene):
    params = PaintParams(lambda_p=12.0, iterations=3)
    exact = fast = None
    for _ in range(3):
        exact = paint(hard_scene, CAMERA, W, H, replace(params, fast=False), previous=exact and exact.state)
        fast = paint(hard_scene, CAMERA, W, H, params, previous=fast and fast.state)
    assert _close_share(fast.image, exact.image) >= SHARE


def test_a_tile_equals_its_crop_with_fast_on(hard_scene):
    for params in (PaintParams(lambda_p=12.0), PaintParams(mapping="depth", lambda_p=3.0, spp=4, noise=0.3)):
        full = paint(hard_scene, CAMERA, W, H, params).state
        region = Region(W, H, 10, 7, 50, 30)
        tile = paint(hard_scene, CAMERA, W, H, params, region=region).state
        np.testing.assert_array_equal(tile.image(), full.image()[7:37, 10:60])
        if full.depth is not None:
            np.testing.assert_array_equal(tile.depth, full.depth.reshape(H, W)[7:37, 10:60].ravel())


def test_bands_given_what_the_image_sees_in_parts_are_its_crops(hard_scene):
    """How Ray paints one painting in bands: the parts of ``seen`` found apart, joined, handed to each band."""
    for params in (PaintParams(lambda_p=12.0), PaintParams(lambda_p=12.0, spp=4, noise=0.3)):
        full = paint(hard_scene, CAMERA, W, H, params).image
        grid = seen_grid(hard_scene, 0.0, CAMERA, W, H, params)
        fine = grid.height // H
        bands = Region(W, H).tiles(17)
        parts = [
            see(hard_scene, 0.0, CAMERA, Region(grid.width, grid.height, 0, fine * b.y0, -1, fine * b.height))
            for b in bands
        ]
        seen = kernels.Seen.joined(parts)
        for band in bands:
            got = paint(hard_scene, CAMERA, W, H, params, region=band, seen=seen).image
            np.testing.assert_array_equal(got, full[band.y0 : band.y0 + band.height])
        with pytest.raises(ValueError, match="seen does not cover"):
            paint(hard_scene, CAMERA, W, H, params, region=bands[0], seen=kernels.Seen.joined(parts[:1]))
    assert seen_grid(hard_scene, 0.0, CAMERA, W, H, PaintParams(fast=False)) is None


def test_the_visibility_pass_sees_what_the_plain_render_hits(hard_scene):
    region = Region(W, H)
    seen = kernels.Seen.empty(W, H)
    visible_faces(hard_scene, 0.0, CAMERA, region, seen)
    plain = paint(hard_scene, CAMERA, W, H, PaintParams(iterations=1, mapping="depth")).state
    # a pixel whose centre sees the sky records the miss depth: the sky and the faces agree
    misses = plain.depth == np.float32(hard_scene.depth_of_miss(np.asarray(CAMERA.eye), 0.0))
    np.testing.assert_array_equal(seen.face < 0, misses)
    # and the distances are the depths along the ray (the camera looks down -z)
    forward = plain.direction[~misses] @ np.float32([0, 0, -1]) if plain.direction is not None else None
    if forward is not None:
        np.testing.assert_allclose(seen.distance[~misses] * forward, plain.depth[~misses], rtol=1e-5)
    assert 0.05 < misses.mean() < 0.95


def test_resolve_seen_agrees_with_embree_wherever_it_decides(hard_scene):
    """Displaced rays of a painted state: each ray the kernel decides has Embree's face and hit."""
    camera = Camera((0.3, 0.2, 0.0), (0.0, -0.2, -1.0), fov=55.0)
    region = Region(W, H)
    seen = kernels.Seen.empty(W, H)
    visible_faces(hard_scene, 0.0, camera, region, seen)
    params = PaintParams(lambda_p=9.0, noise=0.5, iterations=2)
    state = paint(hard_scene, camera, W, H, params).state
    rays = Rays.allocate(region.pixel_count, 1)
    assign_cameras(state, setup_tile(camera, region, params), params, params.focus(camera), rays)
    geometry, tracer = hard_scene.geometry(0.0)
    n = region.pixel_count
    decided = Hits(np.full(n, -7, np.int32), *(np.full(n, np.nan, np.float32) for _ in range(3)))
    pending = np.empty(n, np.int64)
    left = kernels.resolve_seen(
        origins=rays.origins,
        directions=rays.directions,
        count=n,
        plane=kernels.ImagePlane.of(camera, region),
        seen=seen,
        triangles=geometry.triangles,
        hits=decided,
        pending=pending,
        pixels=np.arange(n),
        spp=1,
    )
    truth = tracer.intersect(rays.origins, rays.directions)
    done = np.ones(n, bool)
    done[pending[:left]] = False
    assert 0.7 < done.mean() < 1.0  # most rays decided, some left to Embree
    agree = decided.face[done] == truth.face[done]
    assert agree.mean() > 0.995  # the rest: a pole thinner than a pixel between centres that saw the sky
    hit = done & (truth.face >= 0) & (decided.face == truth.face)
    np.testing.assert_allclose(decided.t[hit], truth.t[hit], rtol=1e-4)
    np.testing.assert_allclose(decided.b1[hit], truth.b1[hit], atol=1e-4)
    np.testing.assert_allclose(decided.b2[hit], truth.b2[hit], atol=1e-4)


def _ref_changed(before: PaintState, after: PaintState, reads, levels: int) -> np.ndarray:
    differs = np.zeros(before.region.pixel_count, bool)
    for name in reads:
        a, b = getattr(before, name), getattr(after, name)
        if name == "color" and levels:
            a, b = np.floor(a * np.float32(levels) + 0.5), np.floor(b * np.float32(levels) + 0.5)
        else:
            a, b = a.view(np.int32), b.view(np.int32)
        differs |= (a != b).reshape(len(differs), -1).any(axis=1)
    return np.flatnonzero(differs)


@pytest.mark.parametrize("levels", [0, 255])
@pytest.mark.parametrize("reads", [("color",), ("color", "depth"), ("normal", "direction")])
def test_changed_pixels_matches_numpy(reads, levels):
    region = Region(40, 10)
    rng = np.random.default_rng(3)
    n = region.pixel_count
    before = PaintState(
        region,
        rng.uniform(0, 1, (n, 3)).astype(np.float32),
        rng.uniform(1, 9, n).astype(np.float32),
        rng.normal(size=(n, 3)).astype(np.float32),
        rng.normal(size=(n, 3)).astype(np.float32),
    )
    after = before.copy()
    for name in ("color", "depth", "normal", "direction"):
        values = getattr(after, name)
        pick = rng.random(n) < 0.3
        values[pick] += np.float32(1e-3)  # less than half a display level: only bits see it
    after.color[rng.random(n) < 0.1] += np.float32(0.01)
    after.depth[5] = np.nan
    before.depth[6] = after.depth[6] = np.nan  # the same NaN is no change
    out = np.empty(n, np.int64)
    count = kernels.changed_pixels(
        before=kernels.channels(before),
        after=kernels.channels(after),
        color="color" in reads,
        channels=kernels.records(reads),
        color_levels=levels,
        out=out,
    )
    expected = _ref_changed(before, after, reads, levels)
    np.testing.assert_array_equal(out[:count], expected)
    assert 0 < count < n
