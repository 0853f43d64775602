"""Primary visibility without the BVH, for eyes that stay put: a ray from a fixed eye is found in the screen
cells of ``screencells.py`` (the triangles that can cover each cell of the image plane), and its face is the
nearest listed triangle that contains it, whenever that answer provably is Embree's.

Provably: every listed triangle is tested with its three edge functions in double precision, each with a
bound of the error Embree makes computing it in single precision (``screencells.ERROR_ULPS`` ulps of the
corners' distance from the eye times the ray's distance from the corners). A triangle is *certain* when the signs of its three edge functions and of its
determinant cannot differ from Embree's and the ray lies more than ``embree.EDGE`` inside it as Embree computes it (so that
Embree's packets do not ask the ray again alone), *missed* when two edge functions certainly differ in sign
or the hit lies certainly behind the eye, and *uncertain* otherwise. The answer is the nearest certain
triangle when no other triangle that is not missed can come as near within both distances' error bounds,
and a miss when every listed triangle is missed. Anything else goes to Embree: a ray near an edge, two
candidates tied in depth (coplanar faces), a grazing ray, a ray from another eye (a moving eye), a ray
outside the cells (beyond the guard band, behind the camera, not finite), a cell whose list is too long.

Embree answers in the very packets it answers with the lists off: a packet of eight consecutive rays that
has one ray the lists cannot answer goes to ``embree.intersect_rays`` whole, so that even the rays whose
answer depends on their neighbours (two faces at exactly the same depth) come out as they do without lists.
"""

from __future__ import annotations

import math

import numba

from .embree import EDGE, intersect_rays
from .jit import jit

_PACKET = 8  # as embree.intersect_rays groups rays

# one face's record for one eye (``screencells.py``): its three edge functions over the image plane, each
# ``E_i(a, b) = A_i a + B_i b + C_i`` at the point ``(a, b)`` (``d.r / d.f``, ``d.u / d.f``) of a ray ``d``
# (the edge function of Embree's unit ray times ``|w|``, ``w = a r + b u + f``), its plane's offset
# (``z = OFFSET / sum E_i`` is the depth of the ray's hit), and the bound of Embree's relative error on t
EDGES, OFFSET, REL_T = 0, 9, 10
RECORD = 12

# why a ray goes to Embree (``reasons`` counts them)
ANSWERED, OTHER_EYE, OUTSIDE, LONG, GRAZING, EDGE_OR_TIE = 0, 1, 2, 3, 4, 5
REASONS = ("answered", "another eye", "outside the cells", "long list", "grazing", "edge or tie")


@numba.njit(inline="always")
def _eye_of(screen, ox, oy, oz):
    """Which of the screen's eyes the ray's (float32) origin is exactly, -1 for none."""
    for e in range(screen.eyes.shape[0]):
        if ox == screen.eyes[e, 0] and oy == screen.eyes[e, 1] and oz == screen.eyes[e, 2]:
            return e
    return -1


@numba.njit(inline="always")
def _answer(screen, origins, directions, s):
    """``(status, face)`` of ray ``s`` from the lists: ANSWERED with its face (-1: it misses), or why Embree must answer instead (REASONS)."""
    e = _eye_of(screen, origins[s, 0], origins[s, 1], origins[s, 2])
    if e < 0:
        return OTHER_EYE, -1
    dx = float(directions[s, 0])
    dy = float(directions[s, 1])
    dz = float(directions[s, 2])
    b = screen.basis
    df = dx * b[2, 0] + dy * b[2, 1] + dz * b[2, 2]
    if not df > 0.0:  # behind the camera, along the image plane, or not finite
        return OUTSIDE, -1
    pa = (dx * b[0, 0] + dy * b[0, 1] + dz * b[0, 2]) / df
    pb = (dx * b[1, 0] + dy * b[1, 1] + dz * b[1, 2]) / df
    gx = pa * screen.scale_x + screen.shift_x
    gy = pb * screen.scale_y + screen.shift_y
    if not (gx >= 0.0 and gx < screen.columns and gy >= 0.0 and gy < screen.rows):
        return OUTSIDE, -1  # beyond the guard band (or NaN)
    cell = int(gy) * screen.columns + int(gx)
    if screen.long[e, cell]:
        return LONG, -1
    best = -1
    best_z = best_lo = best_hi = math.inf
    rival_lo = math.inf  # the nearest any other face that is not missed can be
    for k in range(screen.start[e, cell], screen.start[e, cell + 1]):
        f = screen.faces[k]
        err = screen.errors[k]  # Embree's error on this face's edge functions, anywhere in the cell
        u0 = screen.records[e, f, 0] * pa + screen.records[e, f, 1] * pb + screen.records[e, f, 2]
        u1 = screen.records[e, f, 3] * pa + screen.records[e, f, 4] * pb + screen.records[e, f, 5]
        u2 = screen.records[e, f, 6] * pa + screen.records[e, f, 7] * pb + screen.records[e, f, 8]
        if (u0 > err or u1 > err or u2 > err) and (u0 < -err or u1 < -err or u2 < -err):
            continue  # two edges certainly disagree: Embree misses it too
        det = u0 + u1 + u2
        spread = 3.0 * err
        if not abs(det) > 2.0 * spread:  # grazing: the side it is met from is anybody's guess
            return GRAZING, -1
        z = screen.records[e, f, OFFSET] / det
        rel = screen.records[e, f, REL_T] + spread / abs(det) + 1e-9
        if not rel < 0.5:
            return GRAZING, -1
        if z <= 0.0:  # its plane is met behind the eye (the error cannot flip the sign of t)
            continue
        lo = z * (1.0 - rel)
        hi = z * (1.0 + rel)
        if det < 0.0:
            u0, u1, u2 = -u0, -u1, -u2
        # inside by more than EDGE as Embree computes it: its packets do not ask the ray again alone
        margin = EDGE * (abs(det) + spread) + err
        if u0 >= margin and u1 >= margin and u2 >= margin and z < best_z:
            rival_lo = min(rival_lo, best_lo)
            best, best_z, best_lo, best_hi = f, z, lo, hi
        else:
            rival_lo = min(rival_lo, lo)
    if best < 0:
        return (ANSWERED, -1) if rival_lo == math.inf else (EDGE_OR_TIE, -1)
    if rival_lo > best_hi:
        return ANSWERED, best
    return EDGE_OR_TIE, -1


@jit
def find_faces(screen, embree, origins, directions, rays, face, queue):
    """The closest triangle of each listed ray into ``face``, as ``embree.intersect_rays`` finds it (the same
    face, bit for bit): from the screen cells where they prove the answer, else from Embree. Returns how
    many rays the cells answered.

    screen : bundles.Screen (``on`` False: every ray goes to Embree);  embree : embree.Embree
    origins, directions : (n, 3) float32;  rays : (m,) int64 in screen order;  face : (n,) int32 out
    queue : (m,) int64 scratch: the rays of the packets that go to Embree
    """
    m = len(rays)
    if not screen.on:
        intersect_rays(embree, origins, directions, rays, face, True)
        return 0
    queued = 0
    answered = 0
    for start in range(0, m, _PACKET):
        lanes = min(_PACKET, m - start)
        whole = True
        for lane in range(lanes):
            s = rays[start + lane]
            status, f = _answer(screen, origins, directions, s)
            if status != ANSWERED:
                whole = False
                break
            face[s] = f
        if whole:
            answered += lanes
            continue
        # the packet as it is, in the same lanes: the answers of rays that tie cannot change
        for lane in range(lanes):
            queue[queued] = rays[start + lane]
            queued += 1
    if queued:
        intersect_rays(embree, origins, directions, queue[:queued], face, True)
    return answered


@jit
def reasons(screen, origins, directions, rays, counts):
    """Why each listed ray would go to Embree, or that the cells answer it: ``counts`` (len(REASONS),) int64
    added to, one entry a reason (what ``rcp bench speed`` prints)."""
    for s in rays:
        status, _ = _answer(screen, origins, directions, s) if screen.on else (OTHER_EYE, -1)
        counts[status] += 1
