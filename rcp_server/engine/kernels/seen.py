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
from .projection import EQUIRECT, MONO, SIDE_BY_SIDE, TOP_BOTTOM, locate, target_offset, tile_pixel, to_pixel
from .triangle import corner_and_edges, ray_triangle

SILHOUETTE = 1.1  # the farthest of four neighbouring centres' hits over the nearest, beyond which they
# are two objects, not one surface (a surface at 85 degrees to the view changes by 3% a pixel at 640x360)


IN_FRONT = 1e-3  # how much nearer (relative) than the plane of a ray's face a corner's hit must be to count


@numba.njit(inline="always")
def _corner_in_front(triangles, f, ox, oy, oz, seen, corner, plane, fine, x_off, y_off):
    """Whether one of the four centres around ``corner`` saw, by another face, something nearer than the plane
    of face ``f`` along its own ray (seen from the eye ``o``): an object that stands before ``f`` right beside
    the ray. A corner on the same surface, flat or bulging away, lies on or behind that plane. The grid is
    ``fine`` times the painting; its eye's image starts at ``(x_off, y_off)`` of the painting."""
    ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z = corner_and_edges(triangles, f)
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    reach = (ax - ox) * nx + (ay - oy) * ny + (az - oz) * nz  # the plane's distance along n from the eye
    width = seen.width
    for q in range(4):
        c = corner + (q & 1) + (q >> 1) * width
        g = seen.face[c]
        if g < 0 or g == f:
            continue
        # the centre's ray, as the plain render cast it (projection.target_offset)
        dx, dy, dz = target_offset(plane, (c % width + 0.5) / fine - x_off, (c // width + 0.5) / fine - y_off)
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        across = (dx * nx + dy * ny + dz * nz) / length
        if across == 0.0:
            continue
        t_plane = reach / across
        if t_plane > 0.0 and seen.distance[c] < t_plane * (1.0 - IN_FRONT):
            return True
    return False


@jit
def resolve_seen(origins, directions, count, plane, seen, triangles, hits, pending, pixels, spp):
    """Closest hits of the first ``count`` rays where ``seen`` decides them; returns how many it could not
    decide, whose ray indices it writes to the start of ``pending``.

    origins, directions : (>= count, 3) float32, every origin its pixel's eye (one point per eye: not
    omnidirectional stereo), directions unit length;  plane : a bundles.ImagePlane of the tile
    seen : a bundles.Seen of the camera (its grid: the painting's pixels, or ``fine`` times as many each way)
    triangles : (F, 3, 3) float32
    hits : tracer.Hits of >= count rays, written for the rays decided (t, b1, b2 as
    ``triangle.place_hits`` gives them);  pending : (>= count,) int64 out
    pixels, spp : the tile's pixel of ray ``s`` is ``pixels[s // spp]`` (which eye casts it)
    """
    seen_face, seen_distance, near = seen.face, seen.distance, seen.near
    width = seen.width
    fine = width / plane.full_width
    eye_w = plane.eye_width * fine  # an eye's image, on the grid
    eye_h = plane.eye_height * fine
    forward = plane.basis[2]
    sphere = plane.projection == EQUIRECT
    face, t_hit, b1_hit, b2_hit = hits.face, hits.t, hits.b1, hits.b2
    n_pending = 0
    for s in range(count):
        dx = directions[s, 0]
        dy = directions[s, 1]
        dz = directions[s, 2]
        side = 0
        if plane.layout != MONO:
            i, j = tile_pixel(plane, pixels[s // spp])
            side, _, _ = locate(plane, i, j)
        x, y, ok = to_pixel(plane, side, dx, dy, dz, False)
        # on the grid (its centres on the integers), within the eye's own image
        x = (x + 0.5) * fine - 0.5
        y = (y + 0.5) * fine - 0.5
        x_off = eye_w if side > 0 and plane.layout == SIDE_BY_SIDE else 0.0
        y_off = eye_h if side > 0 and plane.layout == TOP_BOTTOM else 0.0
        if not (ok and x_off <= x < x_off + eye_w - 1 and y_off <= y < y_off + eye_h - 1):
            # behind the eye, a NaN ray, off the eye's grid of centres (or across the sphere's seam): Embree's
            pending[n_pending] = s
            n_pending += 1
            continue
        along = 1.0 if sphere else dx * forward[0] + dy * forward[1] + dz * forward[2]
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
            and _corner_in_front(triangles, best, ox, oy, oz, seen, corner, plane, fine, x_off / fine, y_off / fine)
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


SPLIT = 4.0  # on the sphere, a thin triangle is cut (in space) until it spans at most this many cells each way:
# its edges are curves in the image, nearly straight over a few cells
MARGIN = 0.05  # cells added around each piece on the sphere, besides what its curved edges need
POLE = math.radians(89.0)  # the latitude up to which a piece's bend is estimated (beyond, as there)


@numba.njit(inline="always")
def _bend_margin(ys, y_off, eye_h, big):
    """The cells to grow a piece ``big`` cells across by, at rows ``ys`` of an eye's panorama starting at row
    ``y_off``: how far its curved edges may stray from the straight ones. A chord of length L of a curve of
    curvature k strays L^2 k / 8, and a great circle's image bends by about tan(latitude) pi / H a cell; twice
    that, and :data:`MARGIN` besides."""
    pole = max(abs(0.5 - (ys[0] - y_off + 0.5) / eye_h), abs(0.5 - (ys[1] - y_off + 0.5) / eye_h))
    pole = max(pole, abs(0.5 - (ys[2] - y_off + 0.5) / eye_h)) * math.pi
    return MARGIN + 0.25 * big * big * math.tan(min(pole, POLE)) * math.pi / eye_h


@numba.njit(inline="always")
def _cells(near, xs, ys, z, row0, rows, x_lo, x_hi, y_lo, y_hi, width, margin, wrap):
    """Lower ``near`` to ``z`` in every cell of rows ``row0 .. row0 + rows`` that the triangle ``(xs, ys)`` (grid
    coordinates, centres on the integers) overlaps, grown by ``margin`` cells; the cell columns allowed are
    ``x_lo .. x_hi`` (an eye's image), rows ``y_lo .. y_hi``; ``wrap``: columns wrap around that range."""
    top_y = min(ys[0], ys[1], ys[2]) - margin
    bottom_y = max(ys[0], ys[1], ys[2]) + margin
    first = max(int(math.floor(top_y)), row0, y_lo)
    last = min(int(math.floor(bottom_y)), row0 + rows - 1, y_hi)
    span = x_hi - x_lo + 2  # the eye image's width, for the wrap
    left = int(math.floor(min(xs[0], xs[1], xs[2]) - margin))
    right = int(math.floor(max(xs[0], xs[1], xs[2]) + margin))
    if right - left <= 1 and last - first <= 1:  # a speck: the cells of its box (most triangles of a panorama)
        for cy in range(first, last + 1):
            for cx in range(left, right + 1):
                col = x_lo + (cx - x_lo) % span if wrap else cx
                if col < x_lo or col > x_hi:
                    continue
                cell = (cy - row0) * width + col
                if z < near[cell]:
                    near[cell] = z
        return
    for cy in range(first, last + 1):
        top = cy - margin
        bottom = cy + 1.0 + margin
        lo = math.inf
        hi = -math.inf
        # the triangle's extent within the row's slab: its corners inside, its edges where they cross it
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
        start = int(math.floor(lo - margin))
        stop = int(math.floor(hi + margin))
        if not wrap:
            start = max(start, x_lo)
            stop = min(stop, x_hi)
        for cx in range(start, stop + 1):
            col = x_lo + (cx - x_lo) % span if wrap else cx
            if col > x_hi:
                continue  # the seam's cell, which resolve_seen never reads
            cell = (cy - row0) * width + col
            if z < near[cell]:
                near[cell] = z


@jit
def cover_thin(triangles, eye, plane, rows, near):
    """Where geometry that no centre of the grid may see lies: for each cell of the grid of pixel centres of
    ``plane`` (a bundles.ImagePlane of the grid, whose ``y0`` is the first row of these cells; the cell
    whose top-left centre is pixel (x, y) at ``near[(y - y0) * width + x]``), the least depth of the *thin*
    triangles (``THIN``) that overlap it, for the cells of ``rows`` rows; ``near`` (rows * width,)
    float32 must hold +inf where nothing is written. Depth is view depth on an image plane, the distance
    from the eye on the sphere: what ``resolve_seen`` compares it with.

    A ray that ``resolve_seen`` would decide by the corners' triangles goes to Embree where something thin
    lies nearer than the corners saw: a baluster, a chair leg, a rail between centres that all saw the wall.
    Each eye of a stereo grid projects from its own eye into its own image. triangles : (F, 3, 3) float32;
    eye : (3,) float64. Left out, as rare, and then only their own pixels can be wrong: on an image plane
    triangles reaching behind the eye's plane (they cross the whole screen), on the sphere thin triangles
    around a pole.
    """
    width, row0 = plane.full_width, plane.y0
    sphere = plane.projection == EQUIRECT
    forward = plane.basis[2]
    eye_w = plane.eye_width
    eye_h = plane.eye_height
    xs = np.empty(3)
    ys = np.empty(3)
    px = np.empty(3)
    py = np.empty(3)
    stack = np.empty((64, 3, 3))  # pieces of a triangle on the sphere, cut in space
    sides = (-1, 1) if plane.layout != MONO else (0, 0)
    for n_side in range(1 if plane.layout == MONO else 2):
        side = sides[n_side]
        x_off = eye_w if side > 0 and plane.layout == SIDE_BY_SIDE else 0
        y_off = eye_h if side > 0 and plane.layout == TOP_BOTTOM else 0
        ox = eye[0] + side * plane.half_ipd * plane.basis[0, 0]
        oy = eye[1] + side * plane.half_ipd * plane.basis[0, 1]
        oz = eye[2] + side * plane.half_ipd * plane.basis[0, 2]
        for f in range(triangles.shape[0]):
            z_min = math.inf
            usable = True
            for k in range(3):
                rx = triangles[f, k, 0] - ox
                ry = triangles[f, k, 1] - oy
                rz = triangles[f, k, 2] - oz
                if sphere:
                    z = math.sqrt(rx * rx + ry * ry + rz * rz)
                elif not rx * forward[0] + ry * forward[1] + rz * forward[2] > 1e-6:
                    usable = False
                    break
                else:
                    z = rx * forward[0] + ry * forward[1] + rz * forward[2]
                x, y, ok = to_pixel(plane, side, rx, ry, rz, False)
                usable = usable and ok
                xs[k] = x
                ys[k] = y
                z_min = min(z_min, z)
            if not usable:
                continue
            if sphere:  # across the seam: each corner's longitude the nearest to the first's
                for k in (1, 2):
                    if xs[k] - xs[0] > 0.5 * eye_w:
                        xs[k] -= eye_w
                    elif xs[0] - xs[k] > 0.5 * eye_w:
                        xs[k] += eye_w
                if max(xs[0], xs[1], xs[2]) - min(xs[0], xs[1], xs[2]) > 0.5 * eye_w:
                    continue  # around a pole
            y_lo = min(ys[0], ys[1], ys[2])
            y_hi = max(ys[0], ys[1], ys[2])
            x_lo_t = min(xs[0], xs[1], xs[2])
            x_hi_t = max(xs[0], xs[1], xs[2])
            if y_hi < row0 - 1 or y_lo > row0 + rows + 1:
                continue  # off these rows of the grid
            if not sphere and (max(xs[0], xs[1], xs[2]) < x_off or min(xs[0], xs[1], xs[2]) > x_off + eye_w - 1):
                continue
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
            x_lo, x_hi = x_off, x_off + eye_w - 2
            y_first, y_last = y_off, y_off + eye_h - 2
            if not sphere:
                _cells(near, xs, ys, z_min, row0, rows, x_lo, x_hi, y_first, y_last, width, 0.0, False)
                continue
            # ---- on the sphere: pieces small enough that their curved edges are nearly straight (most thin
            # triangles already are: drawn as projected, without cutting and projecting them again) ----
            if max(x_hi_t - x_lo_t, y_hi - y_lo) <= SPLIT:
                margin = _bend_margin(ys, y_off, eye_h, max(x_hi_t - x_lo_t, y_hi - y_lo))
                _cells(near, xs, ys, z_min, row0, rows, x_lo, x_hi, y_first, y_last, width, margin, True)
                continue
            for k in range(3):
                for q in range(3):
                    stack[0, k, q] = triangles[f, k, q]
            top = 1
            while top > 0:
                top -= 1
                for k in range(3):
                    x, y, _ = to_pixel(
                        plane, side, stack[top, k, 0] - ox, stack[top, k, 1] - oy, stack[top, k, 2] - oz, False
                    )
                    px[k] = x
                    py[k] = y
                for k in (1, 2):
                    if px[k] - px[0] > 0.5 * eye_w:
                        px[k] -= eye_w
                    elif px[0] - px[k] > 0.5 * eye_w:
                        px[k] += eye_w
                big = max(
                    max(px[0], px[1], px[2]) - min(px[0], px[1], px[2]),
                    max(py[0], py[1], py[2]) - min(py[0], py[1], py[2]),
                )
                if big <= SPLIT or top + 2 > stack.shape[0]:
                    margin = _bend_margin(py, y_off, eye_h, big)
                    _cells(near, px, py, z_min, row0, rows, x_lo, x_hi, y_first, y_last, width, margin, True)
                    continue
                # cut the longest edge (in space) at its middle: two pieces
                longest = 0
                best = -1.0
                for k in range(3):
                    length = 0.0
                    for q in range(3):
                        length += (stack[top, (k + 1) % 3, q] - stack[top, k, q]) ** 2
                    if length > best:
                        best = length
                        longest = k
                a = longest
                b = (longest + 1) % 3
                for q in range(3):
                    middle = 0.5 * (stack[top, a, q] + stack[top, b, q])
                    stack[top + 1, 0, q] = stack[top, 0, q]
                    stack[top + 1, 1, q] = stack[top, 1, q]
                    stack[top + 1, 2, q] = stack[top, 2, q]
                    stack[top, b, q] = middle
                    stack[top + 1, a, q] = middle
                top += 2
