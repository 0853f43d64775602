"""Intersection without the BVH where the plain render already knows the answer (the ``fast`` setting).

With the eyes at rest every ray of a painting starts at the camera's eye, so it is a primary ray through
some point of the image plane, and the plain render says which triangle each pixel centre sees. A ray
that crosses the image plane among four pixel centres that saw triangles is tested against those
triangles alone (one to four tests against Embree's tree walk); among four centres that all saw the sky
it misses. Everything else (off screen, behind the eye, a silhouette: centres whose hits lie at
distances apart, a ray that hits none of its candidates) is left to Embree. What this can get wrong is
geometry thinner than the grid of centres that no centre saw: paintings of several samples, which
antialias such geometry, look at a grid twice as fine. The tests bound how often it matters, against
tracing every ray.
"""

from __future__ import annotations

import math

from .jit import jit
from .triangle import ray_triangle

SILHOUETTE = 1.1  # the farthest of four neighbouring centres' hits over the nearest, beyond which they
# are two objects, not one surface (a surface at 85 degrees to the view changes by 3% a pixel at 640x360)


@jit
def resolve_seen(origins, directions, count, plane, seen, triangles, hits, pending):
    """Closest hits of the first ``count`` rays where ``seen`` decides them; returns how many it could not
    decide, whose ray indices it writes to the start of ``pending``.

    origins, directions : (>= count, 3) float32, every origin the camera's eye, directions unit length
    plane : a bundles.ImagePlane of the camera;  seen : a bundles.Seen of the camera
    triangles : (F, 3, 3) float32
    hits : tracer.Hits of >= count rays, written for the rays decided (t, b1, b2 as
    ``triangle.place_hits`` gives them);  pending : (>= count,) int64 out
    """
    basis, tan_half, aspect = plane.basis, plane.tan_half, plane.aspect
    seen_face, seen_distance = seen.face, seen.distance
    width, height = seen.width, seen.height  # its grid of centres: the image's, or a finer one
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
        f00 = seen_face[corner]
        f01 = seen_face[corner + 1]
        f10 = seen_face[corner + width]
        f11 = seen_face[corner + width + 1]
        if f00 < 0 and f01 < 0 and f10 < 0 and f11 < 0:
            face[s] = -1
            continue
        if not (f00 == f01 and f00 == f10 and f00 == f11):
            # several triangles: one surface, or a silhouette whose front object the ray may hit on a face
            # no centre saw (a cylinder's next side). Their distances tell: a jump is a silhouette
            near = math.inf
            far = 0.0
            for q in range(4):
                c = corner + (q & 1) + (q >> 1) * width
                if seen_face[c] >= 0:
                    near = min(near, seen_distance[c])
                    far = max(far, seen_distance[c])
            if far > near * SILHOUETTE:
                pending[n_pending] = s
                n_pending += 1
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
            if f < 0 or (q > 0 and f == f00) or (q > 1 and f == f01) or (q > 2 and f == f10):
                continue
            t, u, v, inside = ray_triangle(triangles, f, ox, oy, oz, dx, dy, dz)
            if inside and t < best_t:
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
