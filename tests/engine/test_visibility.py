"""The screen cells of a fixed eye against Embree: the same face for every ray, wherever the ray goes (inside
faces, on their edges and corners, past the guard band), on soups that make the cells' proof work hard
(shared vertices, grazing and degenerate triangles, coplanar faces, faces across the eye's plane)."""

import numpy as np
import pytest

from rcp_server.camera.camera import RAY_DTYPE, Camera
from rcp_server.engine.kernels import visibility
from rcp_server.engine.kernels.embree import Tracer, intersect_rays
from rcp_server.engine.kernels.screencells import build

CAMERA = Camera((0.2, 0.1, 0.3), (0.0, 0.0, -4.0), fov=60.0)
W, H, GUARD = 160, 120, 12


def _grid(n=24, depth=-4.0, size=4.0, seed=0):
    """A fine, slightly bumpy mesh of 2 n^2 triangles that share their vertices and edges."""
    x, y = np.meshgrid(np.linspace(-size, size, n + 1), np.linspace(-size, size, n + 1))
    z = depth + 0.2 * np.random.default_rng(seed).uniform(-1, 1, x.shape)
    v = np.stack([x, y, z], axis=-1)
    a, b, c, d = v[:-1, :-1], v[:-1, 1:], v[1:, :-1], v[1:, 1:]
    return np.concatenate([np.stack([a, b, d], -2).reshape(-1, 3, 3), np.stack([a, d, c], -2).reshape(-1, 3, 3)])


def _soup(seed=1, count=300):
    rng = np.random.default_rng(seed)
    centre = rng.uniform([-3, -2, -9], [3, 2, -1.5], (count, 1, 3))
    return centre + rng.normal(0.0, 0.4, (count, 3, 3))


def _hard():
    """Coplanar overlapping faces, a grazing face, degenerate ones, faces across and behind the eye."""
    eye = np.array(CAMERA.eye)
    return np.array(
        [
            [[-1, -1, -3], [1, -1, -3], [0, 1, -3]],  # two coplanar faces overlapping
            [[-1, 1, -3], [1, 1, -3], [0, -1, -3]],
            [[-2, -0.5, -2], [2, -0.5, -2.0001], [0, -0.5, -8]],  # nearly edge-on
            [[0, 0, -5], [1, 1, -5], [2, 2, -5]],  # zero area
            [[0.5, 0.5, -5], [0.5, 0.5, -5], [1, 0, -5]],
            [[-3, -1, 2], [3, -1, 2], [0, -1, -6]],  # across the eye's plane, below it
            [[-1, 2, 1], [1, 2, 1], [0, 3, 2]],  # behind the eye
            [eye + [-5, 0.2, 0.5], eye + [5, 0.2, 0.5], eye + [0, 0.3, -6]],  # nearly level with the eye
        ],
        np.float64,
    )


def _screen(triangles, camera=CAMERA, threads=1):
    eyes = np.asarray(camera.eye, np.float64).astype(np.float32)[None]
    return build(triangles, eyes, np.stack(camera.basis()), camera.half_height(), W, H, GUARD, threads)


def _rays(triangles, count, seed):
    """Directions from the eye to random points of the image and its guard band and past them, and to points
    on the triangles' edges and corners, float32 unit."""
    rng = np.random.default_rng(seed)
    r, u, f = camera_basis = np.stack(CAMERA.basis())
    del camera_basis
    reach = CAMERA.half_height() * (1 + 4.0 * GUARD / H)
    a = rng.uniform(-1.6, 1.6, count) * reach * W / H
    b = rng.uniform(-1.6, 1.6, count) * reach
    screen = f + a[:, None] * r + b[:, None] * u
    tri = triangles[rng.integers(0, len(triangles), count)]
    w = rng.uniform(0, 1, (count, 1))
    i = rng.integers(0, 3, count)
    j = (i + 1) % 3
    edges = tri[np.arange(count), i] * (1 - w) + tri[np.arange(count), j] * w
    corners = tri[np.arange(count), i]
    eye = np.asarray(CAMERA.eye)
    d = np.concatenate([screen, edges - eye, corners - eye])
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(RAY_DTYPE)
    return np.broadcast_to(eye.astype(RAY_DTYPE), d.shape).copy(), d


def _both(triangles, origins, directions):
    tracer = Tracer(triangles.astype(RAY_DTYPE))
    screen = _screen(tracer.triangles)
    n = len(origins)
    every = np.arange(n)
    alone = np.full(n, -7, np.int32)
    intersect_rays(tracer.embree, origins, directions, every, alone, True)
    found = np.full(n, -7, np.int32)
    answered = visibility.find_faces(
        screen=screen,
        embree=tracer.embree,
        origins=origins,
        directions=directions,
        rays=every,
        face=found,
        queue=np.empty(n, np.int64),
    )
    counts = np.zeros(len(visibility.REASONS), np.int64)
    visibility.reasons(screen, origins, directions, every, counts)
    return found, alone, answered, counts


@pytest.mark.parametrize(
    "triangles",
    [_grid(), _soup(), np.concatenate([_hard(), _grid(8, -6.0)])],
    ids=["fine mesh", "soup", "hard cases"],
)
def test_the_cells_find_the_face_embree_finds_for_every_ray(triangles):
    origins, directions = _rays(triangles, 4000, 5)
    found, alone, answered, counts = _both(triangles, origins, directions)
    np.testing.assert_array_equal(found, alone)
    # the cells could answer many rays themselves, and sent the others to Embree (here in packets of eight
    # scattered rays, of which few have no ray for Embree)
    assert counts[visibility.ANSWERED] > 0.05 * len(found) and counts[visibility.ANSWERED] >= answered
    assert counts[visibility.OUTSIDE] > 0 and counts[visibility.EDGE_OR_TIE] > 0
    order = np.flatnonzero(np.arange(len(found)) < 4000)  # the screen's rays alone, sorted along the rows
    pa = directions[order] @ np.stack(CAMERA.basis()).T.astype(RAY_DTYPE)
    coherent = order[np.lexsort((pa[:, 0] / pa[:, 2], np.round(pa[:, 1] / pa[:, 2], 1)))]
    found, alone, answered, _ = _both(triangles, origins[coherent], directions[coherent])
    np.testing.assert_array_equal(found, alone)
    assert answered > 0


@pytest.mark.parametrize("threads", [2, 3, 7])
def test_cells_built_on_threads_are_the_cells_built_on_one(threads):
    # each thread takes a share of the faces, then a band of rows; a list or a cover never depends on the split
    triangles = np.concatenate([_hard(), _grid(8, -6.0), _soup()]).astype(RAY_DTYPE)
    one, many = _screen(triangles), _screen(triangles, threads=threads)
    for name in ("start", "cover", "faces", "errors", "nearest", "records", "ids"):
        np.testing.assert_array_equal(getattr(many, name), getattr(one, name), err_msg=name)


def test_a_ray_on_a_shared_edge_or_vertex_goes_to_embree_and_past_the_guard_band_too():
    triangles = _grid(6)
    eye = np.asarray(CAMERA.eye)
    targets = np.concatenate([triangles[:, 0], 0.5 * (triangles[:, 0] + triangles[:, 1])])
    d = targets - eye
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(RAY_DTYPE)
    o = np.broadcast_to(eye.astype(RAY_DTYPE), d.shape).copy()
    tracer = Tracer(triangles.astype(RAY_DTYPE))
    counts = np.zeros(len(visibility.REASONS), np.int64)
    visibility.reasons(_screen(tracer.triangles), o, d, np.arange(len(d)), counts)
    assert counts[visibility.ANSWERED] == 0
    found, alone, _, _ = _both(triangles, o, d)
    np.testing.assert_array_equal(found, alone)


def test_rays_from_another_eye_or_not_finite_go_to_embree():
    triangles = _grid()
    origins, directions = _rays(triangles, 800, 9)
    origins[::3] += np.float32(0.01)  # an eye that moved
    directions[5] = np.nan
    found, alone, _, counts = _both(triangles, origins, directions)
    np.testing.assert_array_equal(found, alone)
    assert counts[visibility.OTHER_EYE] == len(origins[::3]) and found[5] == -1


def test_lists_that_would_cost_more_than_the_bvh_go_to_embree():
    triangles = np.concatenate([_grid(60, -4.0 - 0.01 * k, seed=k) for k in range(3)])  # many layers a cell
    origins, directions = _rays(triangles, 1500, 2)
    found, alone, _, counts = _both(triangles, origins, directions)
    np.testing.assert_array_equal(found, alone)
    assert counts[visibility.LONG] > 0


def test_a_face_hidden_behind_one_that_covers_a_cell_is_dropped_from_it():
    near = np.array([[[-20, -20, -2], [20, -20, -2], [0, 30, -2]]], np.float64)  # covers the whole screen
    far = _grid(30, -9.0)
    tracer = Tracer(np.concatenate([near, far]).astype(RAY_DTYPE))
    screen = _screen(tracer.triangles)
    assert screen.faces.size <= 2 * screen.columns * screen.rows  # the fine mesh behind went
    origins, directions = _rays(np.concatenate([near, far]), 1000, 4)
    found, alone, _, _ = _both(np.concatenate([near, far]), origins, directions)
    np.testing.assert_array_equal(found, alone)


def test_a_face_whose_plane_holds_the_eye_sends_every_ray_it_may_meet_to_embree():
    eye = np.asarray(CAMERA.eye)
    # Embree places hits on it at t ~ 0 anywhere its edge functions agree: the lists cannot know where
    level = np.array([[eye + [-1, 0.0, 0.5], eye + [1, 0.0, 0.5], eye + [0, 0.0, -6]]])
    triangles = np.concatenate([level, _grid(8, -6.0)])
    origins, directions = _rays(triangles, 2000, 5)
    found, alone, _, counts = _both(triangles, origins, directions)
    np.testing.assert_array_equal(found, alone)
    assert (alone == 0).sum() > 100  # Embree does place hits on it
    assert counts[visibility.GRAZING] > 0.5 * len(found)
