"""Primary visibility without the BVH, for eyes that stay put: a ray from a fixed eye is found in the screen
cells of ``screencells.py`` (the triangles that can cover each cell of the image plane), and its face is the
nearest listed triangle that contains it, whenever that answer provably is Embree's.

Provably: every listed triangle is tested with its three edge functions in double precision, each with a
bound of the error Embree makes computing it in single precision (``screencells.ERROR_ULPS`` ulps of the
corners' distance from the eye times the ray's distance from the corners). A triangle is *certain* when the
signs of its three edge functions and of its determinant cannot differ from Embree's and the ray lies more
than ``embree.EDGE`` inside it as Embree computes it (so that Embree's packets do not ask the ray again
alone), *missed* when two edge functions certainly differ in sign
or the hit lies certainly behind the eye, and *uncertain* otherwise. The answer is the nearest certain
triangle when no other triangle that is not missed can come as near within both distances' error bounds,
and a miss when every listed triangle is missed. Anything else goes to Embree: a ray near an edge, two
candidates tied in depth (coplanar faces), a grazing ray, a ray from another eye (a moving eye), a ray
outside the cells (beyond the guard band, behind the camera, not finite), a cell whose list is too long.

The rays the lists cannot answer go to ``embree.intersect_rays`` in packets of their own, eight at a time in
screen order: a ray's answer there does not depend on the rays beside it (a hit near an edge is asked again
alone), so it is the answer it gets with the lists off.
"""

from __future__ import annotations

import math

import numpy as np

from .embree import EDGE, intersect_rays
from .jit import jit

# one face's record for one eye (``screencells.py``): its three edge functions over the image plane, each
# ``E_i(a, b) = A_i a + B_i b + C_i`` at the point ``(a, b)`` (``d.r / d.f``, ``d.u / d.f``) of a ray ``d``
# (the edge function of Embree's unit ray times ``|w|``, ``w = a r + b u + f``), its plane's offset
# (``z = OFFSET / sum E_i`` is the depth of the ray's hit), and the bound of Embree's relative error on t
EDGES, OFFSET, REL_T = 0, 9, 10
RECORD = 12

# why a ray goes to Embree (``reasons`` counts them)
ANSWERED, OTHER_EYE, OUTSIDE, LONG, GRAZING, EDGE_OR_TIE = 0, 1, 2, 3, 4, 5
LONG_CELL = -2  # a cell's cover when its list is too long to pay (-1: test its list, >= 0: the face of all its rays)
REASONS = ("answered", "another eye", "outside the cells", "long list", "grazing", "edge or tie")


@jit
def classify(screen, origins, directions, rays, status, face):
    """What the cells answer for each listed ray: ``status[k]`` for ray ``rays[k]`` (a reason of
    :data:`REASONS`: ANSWERED, or why Embree must answer instead), and where ANSWERED its face into
    ``face[rays[k]]`` (-1: it misses). One call for all the rays: the cells' arrays stay in registers.

    status : (>= m,) int64 out;  face : (n,) int32 out
    """
    # unpacked once: a bundle handed to a function a ray costs more than the ray's whole test
    eyes, b, columns, rows = screen.eyes, screen.basis, screen.columns, screen.rows
    scale_x, shift_x, scale_y, shift_y = screen.scale_x, screen.shift_x, screen.scale_y, screen.shift_y
    start, covers, faces, errors, nearest, records, ids = (
        screen.start,
        screen.cover,
        screen.faces,
        screen.errors,
        screen.nearest,
        screen.records,
        screen.ids,
    )
    # the basis and the first eye as scalars: they stay in registers (read from the arrays, a ray's test
    # cost a quarter more)
    rx, ry, rz, ux, uy, uz, fx, fy, fz = b[0, 0], b[0, 1], b[0, 2], b[1, 0], b[1, 1], b[1, 2], b[2, 0], b[2, 1], b[2, 2]
    first_x, first_y, first_z = eyes[0, 0], eyes[0, 1], eyes[0, 2]
    for k in range(len(rays)):
        s = rays[k]
        ox, oy, oz = origins[s, 0], origins[s, 1], origins[s, 2]
        if ox == first_x and oy == first_y and oz == first_z:  # which eye the ray's (float32) origin is, exactly
            e = 0
        else:
            e = -1
            for q in range(1, eyes.shape[0]):
                if ox == eyes[q, 0] and oy == eyes[q, 1] and oz == eyes[q, 2]:
                    e = q
            if e < 0:
                status[k] = OTHER_EYE
                continue
        dx = float(directions[s, 0])
        dy = float(directions[s, 1])
        dz = float(directions[s, 2])
        df = dx * fx + dy * fy + dz * fz
        if not df > 0.0:  # behind the camera, along the image plane, or not finite
            status[k] = OUTSIDE
            continue
        pa = (dx * rx + dy * ry + dz * rz) / df
        pb = (dx * ux + dy * uy + dz * uz) / df
        gx = pa * scale_x + shift_x
        gy = pb * scale_y + shift_y
        if not (gx >= 0.0 and gx < columns and gy >= 0.0 and gy < rows):
            status[k] = OUTSIDE  # beyond the guard band (or NaN)
            continue
        cell = int(gy) * columns + int(gx)
        cover = covers[e, cell]
        if cover >= 0:  # one face covers the whole cell, provably: no ray of it needs a test
            status[k] = ANSWERED
            face[s] = ids[cover]
            continue
        if cover == LONG_CELL:
            status[k] = LONG
            continue
        best = -1
        best_z = best_lo = best_hi = math.inf
        rival_lo = math.inf  # the nearest any other face that is not missed can be
        verdict = ANSWERED
        for j in range(start[e, cell], start[e, cell + 1]):
            if nearest[j] > best_hi:  # the list runs front to back: nothing further can come nearer
                break
            f = faces[j]
            err = float(errors[j])  # Embree's error on this face's edge functions, anywhere in the cell
            u0 = records[f, 0] * pa + records[f, 1] * pb + records[f, 2]
            u1 = records[f, 3] * pa + records[f, 4] * pb + records[f, 5]
            u2 = records[f, 6] * pa + records[f, 7] * pb + records[f, 8]
            hi = max(u0, max(u1, u2))
            lo = min(u0, min(u1, u2))
            if (hi > err) & (lo < -err):  # two edges certainly disagree: Embree misses it too (one branch,
                continue  # not six: whether a face is missed is a coin toss the CPU cannot predict)
            det = u0 + u1 + u2
            spread = 3.0 * err
            adet = abs(det)
            if not adet > 2.0 * spread:  # grazing: the side it is met from is anybody's guess
                verdict = GRAZING
                break
            z = records[f, OFFSET] / det
            rel = records[f, REL_T] + spread / adet + 1e-9
            if not rel < 0.5:
                verdict = GRAZING
                break
            if z <= 0.0:  # its plane is met behind the eye (the error cannot flip the sign of t)
                continue
            lo_z = z * (1.0 - rel)
            hi_z = z * (1.0 + rel)
            # inside by more than EDGE as Embree computes it: its packets do not ask the ray again alone (and
            # its depth known within 5%: a face dropped from the cell lies 10% deeper than one covering it)
            inner = lo if det > 0.0 else -hi  # the least edge function on the side the ray meets it from
            margin = EDGE * (adet + spread) + err
            if (inner >= margin) & (rel < 0.05) & (z < best_z):
                rival_lo = min(rival_lo, best_lo)
                best, best_z, best_lo, best_hi = f, z, lo_z, hi_z
            else:
                rival_lo = min(rival_lo, lo_z)
        if verdict != ANSWERED:
            status[k] = verdict
        elif best < 0:
            status[k] = ANSWERED if rival_lo == math.inf else EDGE_OR_TIE
            face[s] = -1
        elif rival_lo > best_hi:
            status[k] = ANSWERED
            face[s] = ids[best]
        else:
            status[k] = EDGE_OR_TIE


def find_faces(screen, embree, origins, directions, rays, face, queue) -> int:
    """The closest triangle of each listed ray into ``face``, as ``embree.intersect_rays`` finds it (the same
    face, bit for bit): from the screen cells where they prove the answer, else from Embree. Returns how
    many rays the cells answered. Called from Python: with the cells off, nothing of theirs compiles.

    screen : bundles.Screen (``on`` False: every ray goes to Embree);  embree : embree.Embree
    origins, directions : (n, 3) float32;  rays : (m,) int64 in screen order;  face : (n,) int32 out
    queue : (m,) int64 scratch: the rays that go to Embree
    """
    if not screen.on:
        intersect_rays(embree, origins, directions, rays, face, True)
        return 0
    queued = answer_listed(screen, origins, directions, rays, face, queue)
    if queued:
        intersect_rays(embree, origins, directions, queue[:queued], face, True)
    return len(rays) - queued


@jit
def answer_listed(screen, origins, directions, rays, face, queue):
    """``face`` of the listed rays the cells answer; the others into ``queue``, in order. Returns how many
    were queued (arguments as :func:`find_faces`')."""
    m = len(rays)
    status = queue  # the statuses first; the queue overwrites them behind the ray being read
    classify(screen, origins, directions, rays, status, face)
    queued = 0
    for k in range(m):
        if status[k] != ANSWERED:
            queue[queued] = rays[k]
            queued += 1
    return queued


@jit
def reasons(screen, origins, directions, rays, counts):
    """Why each listed ray would go to Embree, or that the cells answer it: ``counts`` (len(REASONS),) int64
    added to, one entry a reason (what ``rcp bench speed`` prints)."""
    if not screen.on:
        counts[OTHER_EYE] += len(rays)
        return
    status = np.empty(len(rays), np.int64)
    face = np.empty(len(origins), np.int32)
    classify(screen, origins, directions, rays, status, face)
    for k in range(len(rays)):
        counts[status[k]] += 1
