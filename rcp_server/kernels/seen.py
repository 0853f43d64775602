"""Intersection without the BVH where the plain render already knows the answer (the ``fast`` setting).

With the eyes at rest every ray of a painting starts at the camera's eye, so it is a primary ray through
some point of the image plane, and the plain render says which triangle each pixel centre sees. A ray
that crosses the image plane among four pixel centres that saw triangles is tested against those
triangles alone (one to four tests against Embree's tree walk); among four centres that all saw the sky
it misses. Everything else (off screen, behind the eye, a ray that hits none of its candidates) is left
to Embree. What this can get wrong is geometry thinner than a pixel that no neighbouring centre saw:
the tests bound how often, against tracing every ray.
"""

from __future__ import annotations

import math

from .jit import jit


@jit
def resolve_seen(origins, directions, count, plane, seen, triangles, hits, pending):
    """Closest hits of the first ``count`` rays where ``seen`` decides them; returns how many it could not
    decide, whose ray indices it writes to the start of ``pending``.

    origins, directions : (>= count, 3) float32, every origin the camera's eye, directions unit length
    plane : a bundles.ImagePlane of the camera;  seen : (H * W,) int32 the face each pixel centre of the
    full image sees (-1: the sky), row-major;  triangles : (F, 3, 3) float32
    hits : tracer.Hits of >= count rays, written for the rays decided (t, b1, b2 as Embree gives them:
    distance along the direction, weights of the second and third corner);  pending : (>= count,) int64 out
    """
    basis, tan_half, aspect = plane.basis, plane.tan_half, plane.aspect
    width, height = plane.full_width, plane.full_height
    face, t_hit, b1_hit, b2_hit = hits.face, hits.t, hits.b1, hits.b2
    # image-plane coordinates (at unit distance along f) -> continuous pixel coordinates, centres at integers
    x_scale = width / (2.0 * aspect * tan_half)
    y_scale = height / (2.0 * tan_half)
    n_pending = 0
    for s in range(count):
        dx = directions[s, 0]
        dy = directions[s, 1]
        dz = directions[s, 2]
        along = dx * basis[2, 0] + dy * basis[2, 1] + dz * basis[2, 2]
        if not along > 0.0:  # behind the eye, or a NaN ray: Embree's (the tracer masks NaN rays)
            pending[n_pending] = s
            n_pending += 1
            continue
        x = ((dx * basis[0, 0] + dy * basis[0, 1] + dz * basis[0, 2]) / along + aspect * tan_half) * x_scale - 0.5
        y = (tan_half - (dx * basis[1, 0] + dy * basis[1, 1] + dz * basis[1, 2]) / along) * y_scale - 0.5
        if not (0.0 <= x < width - 1 and 0.0 <= y < height - 1):  # off the grid of pixel centres
            pending[n_pending] = s
            n_pending += 1
            continue
        corner = int(y) * width + int(x)
        f00 = seen[corner]
        f01 = seen[corner + 1]
        f10 = seen[corner + width]
        f11 = seen[corner + width + 1]
        if f00 < 0 and f01 < 0 and f10 < 0 and f11 < 0:
            face[s] = -1
            continue
        ox = origins[s, 0]
        oy = origins[s, 1]
        oz = origins[s, 2]
        best = -1
        best_t = math.inf
        best_u = best_v = 0.0
        for q in range(4):
            f = f00 if q == 0 else (f01 if q == 1 else (f10 if q == 2 else f11))
            # each distinct candidate once
            if f < 0 or f == best or (q > 0 and f == f00) or (q > 1 and f == f01) or (q > 2 and f == f10):
                continue
            # Moller-Trumbore in double precision, both sides (Embree culls no back faces)
            ax = triangles[f, 0, 0]
            ay = triangles[f, 0, 1]
            az = triangles[f, 0, 2]
            e1x = triangles[f, 1, 0] - ax
            e1y = triangles[f, 1, 1] - ay
            e1z = triangles[f, 1, 2] - az
            e2x = triangles[f, 2, 0] - ax
            e2y = triangles[f, 2, 1] - ay
            e2z = triangles[f, 2, 2] - az
            px = dy * e2z - dz * e2y
            py = dz * e2x - dx * e2z
            pz = dx * e2y - dy * e2x
            det = e1x * px + e1y * py + e1z * pz
            if det == 0.0:
                continue
            inv = 1.0 / det
            tx = ox - ax
            ty = oy - ay
            tz = oz - az
            u = (tx * px + ty * py + tz * pz) * inv
            if u < 0.0 or u > 1.0:
                continue
            qx = ty * e1z - tz * e1y
            qy = tz * e1x - tx * e1z
            qz = tx * e1y - ty * e1x
            v = (dx * qx + dy * qy + dz * qz) * inv
            if v < 0.0 or u + v > 1.0:
                continue
            t = (e2x * qx + e2y * qy + e2z * qz) * inv
            if 0.0 < t < best_t:
                best, best_t, best_u, best_v = f, t, u, v
        if best < 0:  # none of the candidates: something the centres did not see, Embree finds it
            pending[n_pending] = s
            n_pending += 1
            continue
        face[s] = best
        t_hit[s] = best_t
        b1_hit[s] = best_u
        b2_hit[s] = best_v
    return n_pending
