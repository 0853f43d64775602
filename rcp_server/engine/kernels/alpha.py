"""Which hits land on a texel that lets the ray through (glTF's alpha ``MASK``, OBJ's ``map_d``), compiled.

``pass_masked`` casts those rays again from just past their hit, wherever the traced method intersects (a
tile's iteration, ``iterate.paint_iteration``; the visible-surface pass, ``alphamask.pass_masked``); the
numpy reference of ``masked_rays`` is in ``tests/engine/test_alpha.py``.
"""

from __future__ import annotations

import math

import numpy as np

from .embree import intersect_rays
from .jit import jit
from .triangle import place_hits

MAX_LAYERS = 16  # cut-outs one ray passes through at most; behind more (a dense tree's leaves) it stops
# at the last (a bound on the work, not a visible limit: 16 layers of leaves are opaque anyway)


@jit
def masked_rays(rays, hits, surfaces, out):
    """Of the listed ``rays``, those whose hit lies on a texel with alpha below its material's cutoff; writes
    their indices to the start of ``out`` and returns how many.

    rays : (m,) int64;  hits : tracer.Hits (face -1 on a miss; b1, b2 placed);  surfaces : bundles.Surfaces
    out : (>= m,) int64. Alpha is the texture's coverage (``alpha_texels`` from ``texture_alpha_offset``) in
    [0, 1], bilinear (it is linear coverage, not a display value), wrapping as the colors do.
    """
    face, b1, b2 = hits.face, hits.b1, hits.b2
    uv, texture_id, alphas, alpha_offset = (
        surfaces.uv,
        surfaces.texture_id,
        surfaces.alpha_texels,
        surfaces.texture_alpha_offset,
    )
    widths, heights = surfaces.texture_width, surfaces.texture_height
    face_material, cutoff = surfaces.face_material, surfaces.material_alpha_cutoff
    count = 0
    for s in rays:
        f = face[s]
        if f < 0:
            continue
        limit = cutoff[face_material[f]]
        tid = texture_id[f]
        if limit <= 0.0 or tid < 0 or alpha_offset[tid] < 0:
            continue
        w1 = b1[s]
        w2 = b2[s]
        w0 = 1.0 - w1 - w2
        width = widths[tid]
        height = heights[tid]
        x = (w0 * uv[f, 0, 0] + w1 * uv[f, 1, 0] + w2 * uv[f, 2, 0]) * width - 0.5
        y = (1.0 - (w0 * uv[f, 0, 1] + w1 * uv[f, 1, 1] + w2 * uv[f, 2, 1])) * height - 0.5
        fx0 = math.floor(x)
        fy0 = math.floor(y)
        fx = x - fx0
        fy = y - fy0
        c0 = int(fx0) % width
        c1 = c0 + 1 if c0 + 1 < width else 0
        r0 = int(fy0) % height
        r1 = r0 + 1 if r0 + 1 < height else 0
        a = alpha_offset[tid] + r0 * width
        b = alpha_offset[tid] + r1 * width
        alpha = (
            (1.0 - fx) * (1.0 - fy) * alphas[a + c0]
            + fx * (1.0 - fy) * alphas[a + c1]
            + (1.0 - fx) * fy * alphas[b + c0]
            + fx * fy * alphas[b + c1]
        ) / 255.0
        if alpha < limit:
            out[count] = s
            count += 1
    return count


@jit
def pass_masked(embree, triangles, surfaces, origins, directions, rays, hits, floor, starts, todo, next_todo):
    """Re-casts the listed ``rays`` whose hit is a masked texel (``masked_rays``) from just past that hit,
    until none is (at most ``MAX_LAYERS`` times), writing their new hits into ``hits`` (distance and
    barycentrics placed from the ray's own origin, as ``place_hits`` places every hit).

    embree : tracer.Embree;  triangles : (F, 3, 3) float32;  surfaces : bundles.Surfaces
    origins, directions : (n, 3) float32;  rays : (m,) int64 indices into them and into ``hits``
    floor : the least step past a hit (a millionth of the scene's size), scene units
    starts : (n, 3) float32, todo, next_todo : (>= m,) int64 scratch
    """
    count = masked_rays(rays, hits, surfaces, todo)
    for _ in range(MAX_LAYERS):
        if count == 0:
            return
        listed = todo[:count]
        for s in listed:
            t = float(hits.t[s])
            step = t + max(t * 1e-5, floor)
            for k in range(3):
                starts[s, k] = origins[s, k] + step * directions[s, k]
        intersect_rays(embree, starts, directions, listed, hits.face, np.bool_(False))
        place_hits(origins, directions, listed, triangles, hits)
        count = masked_rays(listed, hits, surfaces, next_todo)
        todo, next_todo = next_todo, todo
