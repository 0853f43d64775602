"""The Embree binding (kernels/embree.py) against embreex, on random and adversarial rays; packets against
single rays."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from rcp_server.engine.kernels.embree import EmbreexScene, Hits, Tracer, intersect_rays, packet_order
from rcp_server.scene.meshes import primitive

RNG = np.random.default_rng(11)


def _soup() -> np.ndarray:
    """A closed sphere, a box, and a grid of shared edges: (F, 3, 3) float32 triangles."""
    parts = [
        (primitive("sphere", subdivisions=3, radius=1.0), (0.0, 0.0, -4.0)),
        (primitive("box", extents=(1.0, 2.0, 0.5)), (1.5, -0.5, -6.0)),
        (primitive("grid", size=(8.0, 8.0), divisions=(8, 8)), (0.0, -2.0, -5.0)),
    ]
    return np.concatenate([p.vertices[p.faces] + np.float32(offset) for p, offset in parts]).astype(np.float32)


def _unit(v: np.ndarray) -> np.ndarray:
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def _rays(triangles: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Ray sets by kind: origins, directions (n, 3) float32."""
    n = 4000
    eye = np.zeros((n, 3), np.float32)
    centroids = triangles.mean(axis=1)
    corners = triangles[RNG.integers(0, len(triangles), n), RNG.integers(0, 3, n)]
    edges = triangles[:, 0] + RNG.uniform(0, 1, (len(triangles), 1)).astype(np.float32) * (
        triangles[:, 1] - triangles[:, 0]
    )
    inside = np.tile(np.float32([0.0, 0.0, -4.0]), (n, 1))  # the sphere's centre
    grazing_origins = np.tile(np.float32([-6.0, -2.0, -5.0]), (n, 1))  # in the grid's plane
    return {
        "random": (RNG.uniform(-3, 3, (n, 3)).astype(np.float32), _unit(RNG.normal(size=(n, 3)))),
        "primary": (eye, _unit(np.stack([RNG.uniform(-1, 1, n), RNG.uniform(-1, 1, n), -np.ones(n)], axis=1))),
        "at centroids": (eye[: len(centroids)], _unit(centroids)),
        "at corners": (eye, _unit(corners)),
        "through edges": (eye[: len(edges)], _unit(edges)),
        "from inside": (inside, _unit(RNG.normal(size=(n, 3)))),
        "grazing": (
            grazing_origins,
            _unit(np.stack([np.ones(n), RNG.uniform(-1e-4, 1e-4, n), RNG.uniform(-1, 1, n)], 1)),
        ),
    }


@pytest.fixture(scope="module")
def soup():
    triangles = _soup()
    return triangles, Tracer(triangles), EmbreexScene(triangles)


@pytest.mark.parametrize(
    "kind", ["random", "primary", "at centroids", "at corners", "through edges", "from inside", "grazing"]
)
def test_the_binding_answers_as_embreex(soup, kind):
    triangles, ours, theirs = soup
    origins, directions = _rays(triangles)[kind]
    mine, reference = ours.intersect(origins, directions), theirs.intersect(origins, directions)
    same = mine.face == reference.face
    # a ray through a shared edge or corner may report either triangle: only there may the faces differ, and
    # then at the same distance
    assert same.mean() >= (0.99 if kind in ("at corners", "through edges") else 0.999)
    hit = same & (reference.face >= 0)
    assert hit.any() or kind == "grazing"
    np.testing.assert_allclose(mine.t[hit], reference.t[hit], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(mine.b1[hit], reference.b1[hit], atol=1e-4)
    np.testing.assert_allclose(mine.b2[hit], reference.b2[hit], atol=1e-4)
    differ = ~same & (reference.face >= 0) & (mine.face >= 0)
    np.testing.assert_allclose(mine.t[differ], reference.t[differ], rtol=1e-4)
    assert not (~same & ((reference.face < 0) != (mine.face < 0))).sum() > 0.001 * len(same)


def test_packets_answer_as_single_rays(soup):
    triangles, ours, _ = soup
    for origins, directions in _rays(triangles).values():
        n = len(origins)
        packets = np.full(n, -7, np.int32)
        intersect_rays(ours.embree, origins, directions, np.arange(n), packets, True)
        singles = np.full(n, -7, np.int32)
        intersect_rays(ours.embree, origins, directions, np.arange(n), singles, False)
        np.testing.assert_array_equal(packets, singles)
        # a ray's answer does not depend on which rays share its packet
        shifted = np.full(n, -7, np.int32)
        intersect_rays(ours.embree, origins, directions, np.arange(3, n), shifted, True)
        np.testing.assert_array_equal(shifted[3:], singles[3:])


@pytest.mark.parametrize(("width", "height", "spp"), [(7, 5, 1), (8, 4, 1), (5, 3, 2), (3, 3, 4), (4, 2, 3)])
def test_packets_in_blocks_take_every_ray_of_a_tile_once_and_answer_as_rows(soup, width, height, spp):
    order = packet_order(width, height, spp, np.full(width * height * spp + 5, -1, np.int64))
    np.testing.assert_array_equal(np.sort(order), np.arange(width * height * spp))
    if spp == 1 and width % 4 == 0:  # the first packet: the block at the top left, 4 x 2 pixels
        np.testing.assert_array_equal(order[:8], [0, 1, 2, 3, width, width + 1, width + 2, width + 3])
    # a grid of primary rays over the soup's edges and corners answers the same in either order
    triangles, ours, _ = soup
    n = 120 * 80
    y, x = np.divmod(np.arange(n), 120)
    directions = _unit(np.stack([(x - 60) / 60.0, (40 - y) / 60.0, -np.ones(n)], axis=1))
    origins = np.zeros((n, 3), np.float32)
    rows, blocks = np.full(n, -7, np.int32), np.full(n, -7, np.int32)
    intersect_rays(ours.embree, origins, directions, np.arange(n), rows, True)
    intersect_rays(ours.embree, origins, directions, packet_order(120, 80, 1, np.empty(n, np.int64)), blocks, True)
    np.testing.assert_array_equal(blocks, rows)


def test_only_the_listed_rays_are_written(soup):
    triangles, ours, _ = soup
    origins, directions = _rays(triangles)["primary"]
    face = np.full(len(origins), -7, np.int32)
    listed = np.arange(0, len(origins), 3)
    intersect_rays(ours.embree, origins, directions, listed, face, True)
    assert (face[listed] != -7).all()
    assert (np.delete(face, listed) == -7).all()


def test_non_finite_rays_miss_without_reaching_embree(soup):
    triangles, ours, _ = soup
    origins, directions = _rays(triangles)["primary"]
    origins, directions = origins.copy(), directions.copy()
    bad = np.zeros(len(origins), bool)
    bad[::5] = True
    directions[::10, 1] = np.nan
    origins[5::10, 0] = np.inf
    hits = ours.intersect(origins, directions)
    assert (hits.face[bad] == -1).all()
    good = ours.intersect(origins[~bad], directions[~bad])
    np.testing.assert_array_equal(hits.face[~bad], good.face)


def test_a_scene_without_triangles_is_refused_by_no_one_and_hits_nothing():
    empty = Tracer(np.zeros((0, 3, 3), np.float32))
    origins = np.zeros((9, 3), np.float32)
    directions = _unit(RNG.normal(size=(9, 3)))
    assert (empty.intersect(origins, directions).face == -1).all()
    assert Hits.misses(3).face.tolist() == [-1, -1, -1]


def test_a_missing_embree_library_is_one_line_and_exit_status_1(tmp_path):
    """The library is found beside embreex, or where RCP_EMBREE_LIBRARY says; where it cannot load, one line."""
    env = {**os.environ, "RCP_EMBREE_LIBRARY": str(tmp_path / "libembree4.so.4")}
    run = subprocess.run(
        [sys.executable, "-m", "rcp_server.cli", "render", "default", "--out", str(tmp_path / "x.png")],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 1
    assert run.stderr.startswith("rcp: error: cannot load the Embree 4 library")
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()
