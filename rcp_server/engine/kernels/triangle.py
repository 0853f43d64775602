"""Where a ray meets a triangle: the one definition of a hit's distance and barycentric weights.

Embree finds which triangle a ray hits first; where on it is computed here, for every hit, whoever found
the triangle (a traced iteration, the pass of what pixel centres see, a pick). So two ways of finding the
same triangle give the same bits, not Embree's float rounding, which a painting's recursion would amplify.
"""

from __future__ import annotations

import numba

from .jit import jit


@numba.njit(inline="always")
def corner_and_edges(triangles, f):
    """Face ``f``'s first corner and its two edges from it, in float64: ``(ax, ay, az, e1x, e1y, e1z, e2x, e2y,
    e2z)``."""
    ax = float(triangles[f, 0, 0])
    ay = float(triangles[f, 0, 1])
    az = float(triangles[f, 0, 2])
    return (
        ax,
        ay,
        az,
        float(triangles[f, 1, 0]) - ax,
        float(triangles[f, 1, 1]) - ay,
        float(triangles[f, 1, 2]) - az,
        float(triangles[f, 2, 0]) - ax,
        float(triangles[f, 2, 1]) - ay,
        float(triangles[f, 2, 2]) - az,
    )


@numba.njit(inline="always")
def ray_triangle(triangles, f, ox, oy, oz, dx, dy, dz):
    """Moller-Trumbore in double precision, both sides (Embree culls no back faces): ``(t, u, v, inside)``
    for the ray ``o + t d`` and triangle ``f`` of ``triangles`` (F, 3, 3); u, v weigh its second and third
    corner; ``inside``: the ray meets the triangle at t > 0 (t, u, v are those of its plane even when not)."""
    # float32 in, float64 throughout: the same bits wherever it is inlined
    ox, oy, oz, dx, dy, dz = float(ox), float(oy), float(oz), float(dx), float(dy), float(dz)
    ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z = corner_and_edges(triangles, f)
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0:  # the ray runs along the triangle's plane
        return 0.0, 0.0, 0.0, False
    inv = 1.0 / det
    tx = ox - ax
    ty = oy - ay
    tz = oz - az
    u = (tx * px + ty * py + tz * pz) * inv
    qx = ty * e1z - tz * e1y
    qy = tz * e1x - tx * e1z
    qz = tx * e1y - ty * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    return t, u, v, u >= 0.0 and v >= 0.0 and u + v <= 1.0 and t > 0.0


@jit
def place_hits(origins, directions, rays, triangles, hits):
    """Distance and barycentric weights of the listed rays' hits, from their face (``ray_triangle``).

    origins, directions : (n, 3) float32;  rays : (m,) int64 the rays to place (their face was found by
    Embree);  triangles : (F, 3, 3) float32;  hits : tracer.Hits of n rays, t, b1, b2 written where face >= 0
    """
    face, t_hit, b1_hit, b2_hit = hits.face, hits.t, hits.b1, hits.b2
    for s in rays:
        f = face[s]
        if f < 0:
            continue
        t, u, v, _ = ray_triangle(
            triangles,
            f,
            origins[s, 0],
            origins[s, 1],
            origins[s, 2],
            directions[s, 0],
            directions[s, 1],
            directions[s, 2],
        )
        t_hit[s] = t
        b1_hit[s] = u
        b2_hit[s] = v
