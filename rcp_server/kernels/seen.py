"""Intersection without the BVH where the plain render already knows the answer (the ``fast`` setting).

With the eyes at rest every ray of a painting starts at the camera's eye, so it is a primary ray through
some point of the image plane, and the plain render says which triangle each pixel centre sees. A ray
that crosses the image plane among four pixel centres that saw triangles is tested against those
triangles alone (one to four tests against Embree's tree walk); among four centres that all saw the sky
it misses. Everything else (off screen, behind the eye, a silhouette: centres whose hits lie at
distances apart, a ray that hits none of its candidates) is left to Embree, and so is a ray through a
cell where geometry thinner than the grid lies nearer than what the corners saw (``cover_thin``: a
baluster, a chair leg, a rail between centres that all saw the wall behind). What this can still get
wrong: the sharp tip of a larger triangle poking into a cell whose corners did not see it, and a thin
part at nearly the corners' depth. The tests bound how often it matters, against tracing every ray.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .jit import jit
from .triangle import corner_and_edges, ray_triangle

SILHOUETTE = 1.1  # the farthest of four neighbouring centres' hits over the nearest, beyond which they
# are two objects, not one surface (a surface at 85 degrees to the view changes by 3% a pixel at 640x360)


IN_FRONT = 1e-3  # how much nearer (relative) than the plane of a ray's face a corner's hit must be to count


@numba.njit(inline="always")
def _corner_in_front(
    triangles, f, ox, oy, oz, seen_face, seen_distance, corner, width, height, basis, tan_half, aspect
):
    """Whether one of the four centres around ``corner`` saw, by another face, something nearer than the plane
    of face ``f`` along its own ray (seen from the eye ``o``): an object that stands before ``f`` right beside
    the ray. A corner on the same surface, flat or bulging away, lies on or behind that plane."""
    ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z = corner_and_edges(triangles, f)
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    reach = (ax - ox) * nx + (ay - oy) * ny + (az - oz) * nz  # the plane's distance along n from the eye
    for q in range(4):
        c = corner + (q & 1) + (q >> 1) * width
        g = seen_face[c]
        if g < 0 or g == f:
            continue
        # the centre's ray, as the plain render cast it (camera.py)
        sx = ((c % width + 0.5) / width * 2.0 - 1.0) * aspect * tan_half
        ty = (1.0 - (c // width + 0.5) / height * 2.0) * tan_half
        dx = basis[2, 0] + sx * basis[0, 0] + ty * basis[1, 0]
        dy = basis[2, 1] + sx * basis[0, 1] + ty * basis[1, 1]
        dz = basis[2, 2] + sx * basis[0, 2] + ty * basis[1, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        across = (dx * nx + dy * ny + dz * nz) / length
        if across == 0.0:
            continue
        t_plane = reach / across
        if t_plane > 0.0 and seen_distance[c] < t_plane * (1.0 - IN_FRONT):
            return True
    return False


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
    seen_face, seen_distance, near = seen.face, seen.distance, seen.near
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
            if near[corner] < math.inf:  # something thin between centres that saw the sky
                pending[n_pending] = s
                n_pending += 1
                continue
            face[s] = -1
            continue
        # the corners' distances: a jump is a silhouette, whose front object the ray may hit on a face no
        # centre saw (a cylinder's next side); a thin part nearer than all of them is one no centre saw
        closest = math.inf
        far = 0.0
        for q in range(4):
            c = corner + (q & 1) + (q >> 1) * width
            if seen_face[c] >= 0:
                closest = min(closest, seen_distance[c])
                far = max(far, seen_distance[c])
        if far > closest * SILHOUETTE or near[corner] < closest * along * (1.0 - NEARER):
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
        if (
            best < 0
            or not (f00 == f01 and f00 == f10 and f00 == f11)
            and _corner_in_front(
                triangles, best, ox, oy, oz, seen_face, seen_distance, corner, width, height, basis, tan_half, aspect
            )
        ):
            # none of the candidates: something the centres did not see; or a corner saw something in front
            # of the face the ray hits, whose next face (one no centre saw) may cover the ray: Embree decides
            pending[n_pending] = s
            n_pending += 1
            continue
        face[s] = best
        t_hit[s] = best_t
        b1_hit[s] = best_u
        b2_hit[s] = best_v
    return n_pending


THIN = 0.75  # a projected triangle whose inscribed circle is at least this wide (in grid cells) holds a
# centre of the grid (any disk of radius sqrt(2)/2 does): some centre sees it unless something is in front
NEARER = 0.01  # how much nearer than what the corners saw (relative) a thin part must be to count


@jit
def cover_thin(triangles, eye, plane, rows, near):
    """Where geometry that no centre of the grid may see lies: for each cell of the grid of pixel centres of
    ``plane`` (a bundles.ImagePlane of the grid, whose ``y0`` is the first row of these cells; the cell
    whose top-left centre is pixel (x, y) at ``near[(y - y0) * width + x]``), the least view depth of the
    *thin* triangles (``THIN``) that overlap it, for the cells of ``rows`` rows; ``near`` (rows * width,)
    float32 must hold +inf where nothing is written.

    A ray that ``resolve_seen`` would decide by the corners' triangles goes to Embree where something thin
    lies nearer than the corners saw: a baluster, a chair leg, a rail between centres that all saw the wall.
    triangles : (F, 3, 3) float32;  eye : (3,) float64. Triangles reaching behind the eye's plane are left out
    (they cross the whole screen; rare, and then only their own pixels can be wrong).
    """
    basis, tan_half, aspect = plane.basis, plane.tan_half, plane.aspect
    width, height, row0 = plane.full_width, plane.full_height, plane.y0
    x_scale = width / (2.0 * aspect * tan_half)
    y_scale = height / (2.0 * tan_half)
    x_shift = aspect * tan_half * x_scale - 0.5
    y_shift = tan_half * y_scale - 0.5
    xs = np.empty(3)
    ys = np.empty(3)
    for f in range(triangles.shape[0]):
        z_min = math.inf
        behind = False
        for k in range(3):
            rx = triangles[f, k, 0] - eye[0]
            ry = triangles[f, k, 1] - eye[1]
            rz = triangles[f, k, 2] - eye[2]
            z = rx * basis[2, 0] + ry * basis[2, 1] + rz * basis[2, 2]
            if not z > 1e-6:
                behind = True
                break
            inv = 1.0 / z
            xs[k] = (rx * basis[0, 0] + ry * basis[0, 1] + rz * basis[0, 2]) * inv * x_scale + x_shift
            ys[k] = y_shift - (rx * basis[1, 0] + ry * basis[1, 1] + rz * basis[1, 2]) * inv * y_scale
            z_min = min(z_min, z)
        if behind:
            continue
        x_lo = min(xs[0], xs[1], xs[2])
        x_hi = max(xs[0], xs[1], xs[2])
        y_lo = min(ys[0], ys[1], ys[2])
        y_hi = max(ys[0], ys[1], ys[2])
        if x_hi < 0.0 or x_lo > width - 1 or y_hi < row0 or y_lo > row0 + rows:
            continue  # off these rows of the grid
        # ---- thin: the inscribed circle's radius, twice the area over the perimeter (at most three times the
        # longest edge, which needs one root where the perimeter needs three) ----
        area2 = abs((xs[1] - xs[0]) * (ys[2] - ys[0]) - (xs[2] - xs[0]) * (ys[1] - ys[0]))
        e0 = (xs[1] - xs[0]) ** 2 + (ys[1] - ys[0]) ** 2
        e1 = (xs[2] - xs[1]) ** 2 + (ys[2] - ys[1]) ** 2
        e2 = (xs[0] - xs[2]) ** 2 + (ys[0] - ys[2]) ** 2
        if area2 * area2 >= 9.0 * THIN * THIN * max(e0, e1, e2):
            continue
        if area2 >= THIN * (math.sqrt(e0) + math.sqrt(e1) + math.sqrt(e2)):
            continue
        # ---- the cells it overlaps: row by row, the triangle's extent within the row's slab ----
        first = max(int(math.floor(y_lo)), row0, 0)
        last = min(int(math.floor(y_hi)), row0 + rows - 1, height - 2)
        for cy in range(first, last + 1):
            top = float(cy)
            bottom = top + 1.0
            lo = math.inf
            hi = -math.inf
            for k in range(3):
                if top <= ys[k] <= bottom:
                    lo = min(lo, xs[k])
                    hi = max(hi, xs[k])
                a = xs[k]
                b = ys[k]
                c = xs[(k + 1) % 3]
                d = ys[(k + 1) % 3]
                if b != d:
                    for edge_y in (top, bottom):
                        if (b - edge_y) * (d - edge_y) <= 0.0:
                            x = a + (edge_y - b) * (c - a) / (d - b)
                            lo = min(lo, x)
                            hi = max(hi, x)
            if lo > hi:
                continue
            for cx in range(max(int(math.floor(lo)), 0), min(int(math.floor(hi)), width - 2) + 1):
                cell = (cy - row0) * width + cx
                if z_min < near[cell]:
                    near[cell] = z_min
