"""The alpha kernel against its numpy reference, and the pass-through's bound on layers."""

from __future__ import annotations

import numpy as np

from rcp_server.engine import kernels
from rcp_server.engine.kernels.alpha import masked_rays
from rcp_server.engine.kernels.embree import Hits


def ref_masked(rays, face, b1, b2, uv, texture_id, alphas, offsets, widths, heights, face_material, cutoff):
    """The rays whose hit lies where the bilinear coverage (wrapping) is below its material's cutoff."""
    out = []
    for s in rays:
        f = face[s]
        if f < 0 or cutoff[face_material[f]] <= 0 or texture_id[f] < 0 or offsets[texture_id[f]] < 0:
            continue
        w = np.array([1 - b1[s] - b2[s], b1[s], b2[s]], np.float64)
        u, v = w @ uv[f].astype(np.float64)
        k = texture_id[f]
        x, y = u * widths[k] - 0.5, (1 - v) * heights[k] - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0

        def alpha(r, c, k=k):
            return alphas[offsets[k] + (int(r) % heights[k]) * widths[k] + int(c) % widths[k]] / 255.0

        a = (1 - fx) * (1 - fy) * alpha(y0, x0) + fx * (1 - fy) * alpha(y0, x0 + 1)
        a += (1 - fx) * fy * alpha(y0 + 1, x0) + fx * fy * alpha(y0 + 1, x0 + 1)
        if a < cutoff[face_material[f]]:
            out.append(s)
    return np.asarray(out, np.int64)


def test_masked_rays_matches_its_numpy_reference():
    rng = np.random.default_rng(5)
    n, faces = 400, 6
    alphas = rng.integers(0, 256, 3 * 5 + 4 * 2).astype(np.uint8)
    surfaces = dict(
        uv=rng.uniform(-1.5, 2.5, (faces, 3, 2)).astype(np.float32),
        texture_id=np.array([0, 1, -1, 0, 1, 2], np.int32),  # texture 2 has no coverage: opaque
        alpha_texels=alphas,
        texture_alpha_offset=np.array([0, 15, -1], np.int64),
        texture_width=np.array([5, 2, 1], np.int64),
        texture_height=np.array([3, 4, 1], np.int64),
        face_material=np.array([1, 1, 1, 0, 2, 2], np.int32),
        material_alpha_cutoff=np.array([0.0, 0.5, 0.8], np.float32),
    )
    bundle = kernels.Surfaces(
        normals=np.zeros((faces, 3, 3), np.float32),
        colors=np.zeros((faces, 3, 3), np.float32),
        texels=np.zeros((1, 3), np.uint8),
        texture_offset=np.zeros(3, np.int64),
        triangles=np.zeros((faces, 3, 3), np.float32),
        face_object=np.zeros(faces, np.int32),
        **surfaces,
    )
    face = rng.integers(-1, faces, n).astype(np.int32)
    b1 = rng.uniform(0, 1, n).astype(np.float32)
    b2 = (rng.uniform(0, 1, n) * (1 - b1)).astype(np.float32)
    hits = Hits(face, np.ones(n, np.float32), b1, b2)
    rays = np.sort(rng.choice(n, 300, replace=False)).astype(np.int64)
    out = np.empty(n, np.int64)
    count = masked_rays(rays=rays, hits=hits, surfaces=bundle, out=out)
    expected = ref_masked(
        rays,
        face,
        b1,
        b2,
        surfaces["uv"],
        surfaces["texture_id"],
        alphas,
        surfaces["texture_alpha_offset"],
        surfaces["texture_width"],
        surfaces["texture_height"],
        surfaces["face_material"],
        surfaces["material_alpha_cutoff"],
    )
    assert 20 < len(expected) < 250  # some masked, some not: the comparison means something
    np.testing.assert_array_equal(out[:count], expected)
