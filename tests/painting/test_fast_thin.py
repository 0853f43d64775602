"""The fast path on thin geometry, seen from inside a room: railings of bars half a pixel wide in front of a
textured wall, a chair on thin legs. No pixel centre may see a bar, so the visible-surface grid alone would
paint the wall through it; ``kernels.cover_thin`` marks where such parts lie and their rays go to Embree."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import CAMERA, facing_plane, make_scene, translate

from rcp_server.camera.camera import Camera, Region
from rcp_server.camera.camera import project as camera_project
from rcp_server.engine import kernels
from rcp_server.engine.kernels.embree import Hits
from rcp_server.painting.loop import paint
from rcp_server.painting.raytrace import Rays, assign_cameras, setup_tile, thin_parts, visible_faces
from rcp_server.scene.meshes import primitive
from rcp_server.scene.scene import Light, SceneObject
from rcp_server.settings.params import PaintParams

W, H = 128, 72  # a pixel is 0.016 x depth wide: 0.08 at depth 5
BAR = 0.03  # under half a pixel at depth 5
BAR_COLOR = (0.9, 0.9, 0.1)
LAMBDA = {"color": 12.0, "depth": 3.0, "normal": 14.0}


def _box(name: str, size, at, color) -> SceneObject:
    part = primitive("box", extents=size).tinted(color)
    return SceneObject(name, part, [(translate(*at), part)])


@pytest.fixture(scope="module")
def room():
    rng = np.random.default_rng(3)
    texture = rng.uniform(0, 1, (32, 32, 3)).astype(np.float32)
    objects = [
        _box("room", (12.0, 6.0, 16.0), (0.0, 0.5, -3.0), (0.85, 0.8, 0.7)),  # we stand inside it
        facing_plane(10.5, size=(11.0, 5.0), divisions=(4, 2), texture=texture, uv_repeat=(3, 1), name="wall"),
        _box("rail", (4.0, BAR, BAR), (-0.5, 0.4, -5.0), (0.1, 0.1, 0.1)),
    ]
    objects += [
        _box(f"bar{k}", (BAR, 1.6, BAR), (-2.3 + 0.3 * k + 0.013 * k, -0.4, -5.0), BAR_COLOR) for k in range(13)
    ]
    objects += [_box("seat", (1.0, 0.08, 1.0), (2.0, -1.2, -4.0), (0.6, 0.2, 0.1))]
    objects += [
        _box(f"leg{k}", (0.03, 1.2, 0.03), (2.0 + dx, -1.85, -4.0 + dz), (0.3, 0.15, 0.05))
        for k, (dx, dz) in enumerate([(-0.45, -0.45), (0.45, -0.45), (-0.45, 0.45), (0.45, 0.45)])
    ]
    light = Light(tuple(np.array([-0.3, -1.0, -0.4]) / np.linalg.norm([-0.3, -1.0, -0.4])), 0.3)
    return make_scene(objects, light=light)


def _displaced_rays(scene) -> tuple[Rays, Hits]:
    """The rays of a painted second iteration of ``scene`` (lambda 9, noise 0.5) and what Embree says they hit."""
    params = PaintParams(lambda_p=9.0, noise=0.5, iterations=2)
    state = paint(scene, CAMERA, W, H, params).state
    rays = Rays.allocate(W * H, 1)
    assign_cameras(state, setup_tile(CAMERA, Region(W, H), params), params, params.focus(CAMERA), rays)
    return rays, scene.geometry(0.0)[1].intersect(rays.origins, rays.directions)


def _decided(scene, rays: Rays, seen: kernels.Seen, camera: Camera = CAMERA) -> tuple[np.ndarray, Hits]:
    """Which rays ``kernels.resolve_seen`` decides with ``seen`` (of ``camera``'s painting, one ray a pixel), (n,)
    bool, and the hits it gives them."""
    n = seen.width * seen.height
    hits = Hits.misses(n)
    hits.face[:] = -7
    pending = np.empty(n, np.int64)
    left = kernels.resolve_seen(
        origins=rays.origins,
        directions=rays.directions,
        count=n,
        plane=kernels.ImagePlane.of(camera, Region(seen.width, seen.height)),
        seen=seen,
        triangles=scene.geometry(0.0)[0].triangles,
        hits=hits,
        pending=pending,
        pixels=np.arange(n),
        spp=1,
    )
    done = np.ones(n, bool)
    done[pending[:left]] = False
    return done, hits


def _close_share(a: np.ndarray, b: np.ndarray) -> float:
    return float((np.abs(a - b).max(axis=2) <= 2 / 255 + 1e-6).mean())


@pytest.mark.parametrize("mapping", sorted(LAMBDA))
@pytest.mark.parametrize("spp, noise", [(1, 0.0), (1, 0.3), (4, 0.3)])
def test_fast_holds_on_thin_parts_seen_from_inside_a_room(room, mapping, spp, noise):
    params = PaintParams(mapping=mapping, lambda_p=LAMBDA[mapping], spp=spp, noise=noise)
    exact = paint(room, CAMERA, W, H, replace(params, fast=False)).image
    fast = paint(room, CAMERA, W, H, params).image
    assert _close_share(fast, exact) >= 0.99


def test_no_centre_sees_the_bars_and_yet_no_ray_is_decided_through_them(room):
    region = Region(W, H)
    seen = kernels.Seen.empty(W, H)
    visible_faces(room, 0.0, CAMERA, region, seen)
    geometry = room.geometry(0.0)[0]
    tint = primitive("box", extents=(1, 1, 1)).tinted(BAR_COLOR).corner_colors[0, 0]
    bar = np.all(geometry.colors[:, 0] == tint, axis=1)  # (F,) the bars' faces
    seen_bars = bar[seen.face[seen.face >= 0]].mean()
    assert seen_bars < 0.02  # a few centres: most of the bars lie between them
    rays, truth = _displaced_rays(room)
    n = region.pixel_count

    def decided_wrongly(with_thin_parts: bool) -> int:
        grid = kernels.Seen(seen.face, seen.distance, np.full(n, np.inf, np.float32), W, H)
        if with_thin_parts:
            thin_parts(room, 0.0, CAMERA, region, grid)
        done, hits = _decided(room, rays, grid)
        return int((done & (hits.face != truth.face)).sum())

    hit_bars = bar[truth.face[truth.face >= 0]].sum()
    assert hit_bars > 20  # displaced rays do meet the bars ...
    assert decided_wrongly(False) > 10  # ... which the centres alone would paint through
    assert decided_wrongly(True) <= 2


def test_cover_thin_marks_every_cell_a_thin_triangle_crosses_and_nothing_far_from_one():
    """Against a numpy reference: points sampled densely on each triangle, projected to the grid."""
    rng = np.random.default_rng(5)
    width, height = 40, 30
    eye = np.zeros(3)
    tan_half, aspect = np.tan(np.radians(30.0)), width / height
    # slivers and specks (thin) and a few large triangles (not thin) at depths 3 to 9
    centers = np.stack([rng.uniform(-3, 3, 60), rng.uniform(-2, 2, 60), rng.uniform(-9, -3, 60)], axis=1)
    spans = np.where(np.arange(60)[:, None, None] < 50, 0.02, 1.5) * rng.normal(size=(60, 3, 3))
    spans[:50, :, 0] *= 40.0  # long in x, thin in y: rails
    triangles = (centers[:, None, :] + spans).astype(np.float32)
    near = np.full(width * height, np.inf, np.float32)
    kernels.cover_thin(
        triangles=triangles,
        eye=eye,
        plane=kernels.ImagePlane.of(CAMERA, Region(width, height)),  # r = +x, u = +y, f = -z
        rows=height,
        near=near,
    )
    x_scale, y_scale = width / (2 * aspect * tan_half), height / (2 * tan_half)

    def project(points):
        z = -points[..., 2]
        return (points[..., 0] / z + aspect * tan_half) * x_scale - 0.5, (tan_half - points[..., 1] / z) * y_scale - 0.5

    w = rng.dirichlet(np.ones(3), 4000)
    for tri in triangles:
        x, y = project(tri)
        area2 = abs((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]))
        perimeter = sum(np.hypot(x[k] - x[k - 1], y[k] - y[k - 1]) for k in range(3))
        if area2 >= kernels.seen.THIN * perimeter:
            continue
        px, py = project(w @ tri.astype(np.float64))
        inside = (px >= 0) & (px < width - 1) & (py >= 0) & (py < height - 1)
        cells = np.floor(py[inside]).astype(int) * width + np.floor(px[inside]).astype(int)
        assert (near[cells] <= (-tri[:, 2]).min() + 1e-5).all()
    marked = np.isfinite(near)
    assert 0.02 < marked.mean() < 0.6  # the rails cross many cells, the large triangles none


def test_a_panel_just_before_a_wall_is_never_decided_through():
    """A finely cut panel 0.3% nearer than the textured wall behind it (a picture on a wall, a door in its
    frame): its triangles are not thin, but a ray near its edge may hit one no centre saw while the corners'
    wall face is hit too; a corner that saw something before the plane of the ray's face sends it to Embree."""
    rng = np.random.default_rng(9)
    texture = rng.uniform(0, 1, (32, 32, 3)).astype(np.float32)
    wall = facing_plane(6.0, size=(12.0, 7.0), divisions=(3, 2), texture=texture, name="wall")
    panel = facing_plane(5.982, size=(3.1, 2.3), divisions=(40, 30), color=(0.9, 0.3, 0.2), center=(0.4, 0.2))
    scene = make_scene([wall, panel])
    region = Region(W, H)
    seen = kernels.Seen.empty(W, H)
    visible_faces(scene, 0.0, CAMERA, region, seen)
    thin_parts(scene, 0.0, CAMERA, region, seen)
    rays, truth = _displaced_rays(scene)
    done, hits = _decided(scene, rays, seen)
    assert done.mean() > 0.8  # the shortcut still decides most rays
    wrong = done & (hits.face != truth.face)
    # only ties may differ: a ray through an edge the two faces share, at the same distance
    np.testing.assert_allclose(hits.t[wrong], truth.t[wrong], rtol=1e-6)


def test_cover_thin_on_the_sphere_marks_every_cell_a_thin_part_crosses():
    """The panorama's grid: thin triangles all around the eye, long ones whose edges curve in the image, some
    across the seam behind and high towards a pole; every point of each (sampled densely, projected by
    ``camera.project``) lies in a cell marked no farther than the triangle's nearest corner."""
    rng = np.random.default_rng(8)
    width, height = 96, 48
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), projection="equirect")
    n = 80
    direction = rng.normal(size=(n, 3))
    direction[:10] = (0.0, 0.1, 1.0)  # behind: across the seam
    direction[10:16] = (0.3, 2.5, -0.4)  # high: near the pole
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centers = direction * rng.uniform(3, 9, (n, 1))
    spans = 0.01 * rng.normal(size=(n, 3, 3))
    spans[:, :, 0] += rng.uniform(-3, 3, (n, 3))  # long along x: rails that curve in the panorama
    triangles = (centers[:, None, :] + spans).astype(np.float32)
    region = Region(width, height)
    near = np.full(width * height, np.inf, np.float32)
    kernels.cover_thin(
        triangles=triangles, eye=np.zeros(3), plane=kernels.ImagePlane.of(camera, region), rows=height, near=near
    )
    w = rng.dirichlet(np.ones(3), 20000)
    checked = 0
    for tri in triangles.astype(np.float64):
        x, y, _ = camera_project(camera, region, np.zeros(3, np.int64), tri)
        x = np.where(x - x[0] > width / 2, x - width, np.where(x[0] - x > width / 2, x + width, x))
        area2 = abs((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]))
        perimeter = sum(np.hypot(x[k] - x[k - 1], y[k] - y[k - 1]) for k in range(3))
        if area2 >= kernels.seen.THIN * perimeter or np.ptp(x) > width / 2:
            continue
        points = w @ tri
        px, py, _ = camera_project(camera, region, np.zeros(len(points), np.int64), points)
        inside = (px >= 0) & (px < width - 1) & (py >= 0) & (py < height - 1)  # not the seam, not the poles
        cells = np.floor(py[inside]).astype(int) * width + np.floor(px[inside]).astype(int)
        assert (near[cells] <= np.linalg.norm(tri, axis=1).min() + 1e-4).all()
        checked += 1
    assert checked > 40


def test_no_ray_of_a_panorama_is_decided_through_the_bars(room):
    """The room all around: the bars ahead, the chair's legs, the room's walls behind and beside."""
    camera = CAMERA.moved(projection="equirect")
    width, height = 2 * H, H
    region = Region(width, height)
    seen = kernels.Seen.empty(width, height)
    visible_faces(room, 0.0, camera, region, seen)
    params = PaintParams(lambda_p=9.0, noise=0.5, iterations=2)
    state = paint(room, camera, width, height, params).state
    rays = Rays.allocate(width * height, 1)
    assign_cameras(state, setup_tile(camera, region, params), params, params.focus(camera), rays)
    truth = room.geometry(0.0)[1].intersect(rays.origins, rays.directions)
    n = region.pixel_count
    grid = kernels.Seen(seen.face, seen.distance, np.full(n, np.inf, np.float32), width, height)
    thin_parts(room, 0.0, camera, region, grid)
    done, hits = _decided(room, rays, grid, camera)
    assert done.mean() > 0.5  # the grid decides most rays ...
    assert int((done & (hits.face != truth.face)).sum()) <= 2  # ... and almost none wrongly
