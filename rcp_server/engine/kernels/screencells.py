"""The screen cells of ``visibility.py``, built once a painting: for each eye at rest, cells of
``CELL`` x ``CELL`` pixels over its image and a guard band around it, each listing every triangle whose
projection can cover a point of the cell.

Conservative everywhere it matters:

- a triangle's projection is bounded by its corners' projections after clipping it to ``z >= eps`` (z the
  depth along the view axis), where ``eps`` is small enough that what the clip removes (its points at
  ``0 < z < eps``, no nearer to the eye than its plane) projects beyond every cell; a triangle whose plane
  passes through the eye is listed everywhere; nothing behind the eye is ever hit by a ray of the cells;
- a triangle is dropped from a cell only when another one covers the whole cell and lies provably nearer
  than Embree can ever place the dropped one (its plane's distance from the eye);
- a cell whose list stays longer than ``LONGEST`` is marked long: its rays go to Embree.

The kernel's records hold, for every face and eye, what its edge functions and distance need in double
precision and the bounds of Embree's single-precision errors on them.
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from .bundles import NO_SCREEN, Screen
from .embree import EDGE
from .jit import jit
from .visibility import LONG_CELL, OFFSET, RECORD, REL_T

CELL = 4  # pixels a side
LONGEST = 24  # triangles a cell may list; a longer list goes to Embree (it would cost more than the BVH)
GUARD_SHARE = 0.25  # the guard band is at most this share of the image's smaller side, each side
PAD = 0.02  # cells each side of a face's projection: Embree's float32 hits may stray past it (by ~1e-5 rad)
T_ULPS = 8.0  # bound of Embree's float32 error on the numerator of t, in ulps of what it multiplies
HIDDEN = 1.1  # a face deeper than this times the depth of one that covers the cell is dropped from it
ERROR_ULPS = 64.0  # bound of Embree's float32 error, in ulps of the magnitudes it multiplies
VARIABLE = "RCP_SCREEN_CELLS"
MODES = ("auto", "on", "off")
"""``RCP_SCREEN_CELLS``: ``auto`` (the default) builds screen cells for a painting that casts at least ``PAYS``
rays a triangle of the scene, and keeps them where they answer its surfaces (:func:`answers`); ``on`` for every
painting they apply to; ``off`` (or ``0``) builds none: every ray goes to Embree. The pictures are the same in
every mode. Measured side by side (``rcp bench speed``, and a painting with the cells on and off in turn), the
cells pay where each triangle is met by many rays (a large painting, several samples a pixel) and lose where a
painting casts few rays a triangle, or where its triangles crowd past ``LONGEST`` a cell (a fine mesh far away:
those rays go to Embree after the cells' test)."""
PAYS = 48.0
LONG_SHARE = 0.25  # at most this share of the cells that list a face may be long for ``auto`` to keep them


def mode() -> str:
    """The mode of ``RCP_SCREEN_CELLS`` (:data:`MODES`); raises ValueError for another value."""
    given = os.environ.get(VARIABLE, "auto").strip().lower()
    given = {"0": "off", "1": "on", "false": "off", "true": "on", "": "auto"}.get(given, given)
    if given not in MODES:
        raise ValueError(f"{VARIABLE} is one of {', '.join(MODES)}, not {given!r}")
    return given


def answers(screen: Screen) -> bool:
    """Whether built cells answer the surfaces they list: at most ``LONG_SHARE`` of the cells that list a face
    are long (their rays would take the cells' test and Embree's both)."""
    long = int((screen.cover == LONG_CELL).sum())
    listing = long + int((np.diff(screen.start, axis=1) > 0).sum())
    return long <= LONG_SHARE * listing


def pays(rays: int, faces: int, chosen: str) -> bool:
    """Whether the cells are worth building in mode ``chosen`` (:data:`MODES`) for a painting of ``rays`` rays
    over ``faces`` triangles."""
    return chosen == "on" or (chosen == "auto" and rays >= PAYS * faces)


BYTES = 4
"""Bytes a pixel the cells of an eye's image take at most (``pixel_bytes`` declares them: a painted pixel's
budget is 64 bytes): a start and a cover (int32 each) a cell, and an entry of the lists (a face, int32,
an error and a nearest depth, float32) takes 12 bytes; past the budget, the cells with the longest lists
are long: their rays go to Embree."""


def guard_pixels(lambda_p: float, noise: float, width: int, height: int) -> int:
    """How far past the image the cells reach, pixels: the largest displacement a painting makes with
    ``lambda_p`` (its largest, overrides included) and ``noise``, within ``GUARD_SHARE`` of the height. Rays
    beyond it are asked of Embree, so this is a matter of speed, not of what a ray finds."""
    return int(min(math.ceil(abs(lambda_p) * (1.0 + noise) * math.sqrt(3.0)) + 2, GUARD_SHARE * min(width, height)))


def build(
    triangles: np.ndarray,
    eyes: np.ndarray,
    basis: np.ndarray,
    tan_half: float,
    width: int,
    height: int,
    guard: int,
    threads: int = 1,
) -> Screen:
    """The screen cells of ``eyes`` (E, 3) float32 (the rays' own origins, exactly), looking along ``basis``
    (3, 3) float64 rows ``r, u, f`` with a vertical half field ``tan_half``, for an eye's image of
    ``width x height`` pixels and a guard band of ``guard`` pixels; ``triangles`` (F, 3, 3) float32, Embree's.
    At most ``BYTES`` a pixel each eye; ``NO_SCREEN`` for an image too small to hold cells. ``threads`` build
    it side by side, each its share of the faces, then its band of rows (a painting waits for its cells)."""
    with ThreadPoolExecutor(threads) as pool:
        return _build(triangles, eyes, basis, tan_half, width, height, guard, threads, pool)


def _build(triangles, eyes, basis, tan_half, width, height, guard, threads, pool) -> Screen:
    """:func:`build` on the threads of ``pool``."""
    clock = time.thread_time()
    helpers = 0.0  # the thread time of the work done on the pool's threads
    aspect = width / height
    columns = -(-(width + 2 * guard) // CELL)
    rows = -(-(height + 2 * guard) // CELL)
    # cell coordinates of a direction with dr/df = a, du/df = b: gx = a * scale_x + shift_x, gy likewise
    scale_x = width / (2.0 * aspect * tan_half * CELL)
    shift_x = (0.5 * width + guard) / CELL
    scale_y = -height / (2.0 * tan_half * CELL)
    shift_y = (0.5 * height + guard) / CELL
    reach = math.hypot(
        max(shift_x, columns - shift_x) / scale_x, max(shift_y, rows - shift_y) / abs(scale_y)
    )  # the farthest point of the cells from the view axis, on the image plane
    starts, covers, lists, records = [], [], [], []
    errors, ids, nearest = [], [], []
    most = (BYTES * width * height - 8 * (columns * rows + 1)) // 12  # entries of all lists, each eye
    if most <= 0:  # an image too small for cells
        return NO_SCREEN
    frame = np.array([scale_x, shift_x, scale_y, shift_y])
    for eye in eyes:
        (start, cover, faces, error, near), record, seconds = _eye_lists(
            triangles, eye, basis, reach, frame, columns, rows, most, pool, threads
        )
        helpers += seconds
        # the listed faces renumbered in the order the lists first name them, their records in that order:
        # the faces of a cell lie side by side in memory
        named, local = _first_named(faces, len(record), sum(len(r) for r in records))
        starts.append(start + sum(len(f) for f in lists))
        covers.append(np.where(cover >= 0, local[np.maximum(cover, 0)], cover))
        lists.append(local[faces])
        errors.append(error)
        nearest.append(near)
        records.append(record[named])
        ids.append(named)
    return Screen(
        on=True,
        eyes=np.asarray(eyes, np.float32).reshape(-1, 3),
        basis=np.ascontiguousarray(basis, np.float64),
        scale_x=scale_x,
        shift_x=shift_x,
        scale_y=scale_y,
        shift_y=shift_y,
        columns=columns,
        rows=rows,
        start=np.stack(starts).astype(np.int32),
        cover=np.stack(covers).astype(np.int32),
        faces=np.concatenate(lists).astype(np.int32),
        errors=np.concatenate(errors),
        nearest=np.concatenate(nearest),
        records=np.concatenate(records),
        ids=np.concatenate(ids).astype(np.int32),
        seconds=time.thread_time() - clock + helpers,
    )


def _eye_lists(triangles, eye, basis, reach, frame, columns, rows, most, pool, threads):
    """The lists of one eye's cells (``_cap``'s five arrays), the records of every face (``_faces``) and the
    thread time spent on the pool: each thread takes its share of the faces, then its band of rows."""
    count = len(triangles)
    record = np.zeros((count, RECORD))  # zeros: a record pads its last word
    plane, spread = np.empty(count), np.empty((count, 5))
    cells, live = np.empty((count, 4), np.int64), np.empty(count, np.bool_)
    grid = np.array([columns, rows, LONGEST], np.int64)
    parts = np.linspace(0, count, threads + 1).astype(np.int64)

    def faces(k):
        share = slice(parts[k], parts[k + 1])
        _faces(
            triangles[share],
            eye,
            basis,
            reach,
            frame,
            grid,
            record[share],
            plane[share],
            spread[share],
            cells[share],
            live[share],
        )

    bands = np.linspace(0, rows, threads + 1).astype(np.int64)
    _, faces_seconds = _split(pool, threads, faces)
    filled, fill_seconds = _split(
        pool,
        threads,
        lambda k: _fill(cells, live, record, plane, spread, grid, frame, bands[k], bands[k + 1]),
    )
    offsets = np.cumsum([0] + [len(part[2]) for part in filled])  # where each band's entries begin
    lists = _cap(
        np.concatenate([[0]] + [part[0][1:] + offset for part, offset in zip(filled, offsets, strict=False)]),
        *(np.concatenate([part[at] for part in filled]) for at in range(1, 5)),
        LONGEST,
        most,
    )
    return lists, record, faces_seconds + fill_seconds


def _split(pool, threads, work):
    """``work(k)`` for every share ``k`` of ``threads``, side by side on ``pool``: the results in order, and the
    thread time they took in all."""

    def timed(k):
        clock = time.thread_time()
        return work(k), time.thread_time() - clock

    done = list(pool.map(timed, range(threads)))
    return [result for result, _ in done], sum(seconds for _, seconds in done)


def _faces(triangles, eye, basis, reach, frame, grid, record, plane, spread, cells, live) -> None:
    """Per face, for rays from ``eye``: the kernel's record (F, RECORD) float64; its plane's distance from the
    eye (F,) float64; what Embree's error on its edge functions scales with (F, 5) float64: its centre from the
    eye (3), its corners' farthest distance from the eye times ``ERROR_ULPS`` ulps, its radius; the cells its
    projection may cover ``(x0, x1, y0, y1)`` (F, 4) int64, inclusive, and whether it may cover any (F,) bool.
    frame : scale_x, shift_x, scale_y, shift_y;  grid : columns, rows"""
    _face_kernel(
        triangles=triangles,
        eye=eye.astype(np.float64),
        basis=np.ascontiguousarray(basis, np.float64),
        reach=reach,
        ulp=ERROR_ULPS * 2.0**-24,
        frame=frame,
        grid=grid,
        record=record,
        plane=plane,
        spread=spread,
        cells=cells,
        live=live,
    )


@jit
def _face_kernel(triangles, eye, basis, reach, ulp, frame, grid, record, plane, spread, cells, live):
    """``_faces``, a face at a time."""
    corner = np.empty((3, 3))
    scale_x, shift_x, scale_y, shift_y = frame[0], frame[1], frame[2], frame[3]
    columns, rows = grid[0], grid[1]
    for f in range(len(triangles)):
        # corners from the eye in the camera's frame: x along r, y along u, z along f
        for i in range(3):
            px = triangles[f, i, 0] - eye[0]
            py = triangles[f, i, 1] - eye[1]
            pz = triangles[f, i, 2] - eye[2]
            for k in range(3):
                corner[i, k] = px * basis[k, 0] + py * basis[k, 1] + pz * basis[k, 2]
        # the edge function of corner i on the image plane: (a_j x a_k) . (a r + b u + f)
        nx = ny = nz = 0.0
        for i in range(3):
            j = (i + 1) % 3
            k = (i + 2) % 3
            cx = corner[j, 1] * corner[k, 2] - corner[j, 2] * corner[k, 1]
            cy = corner[j, 2] * corner[k, 0] - corner[j, 0] * corner[k, 2]
            cz = corner[j, 0] * corner[k, 1] - corner[j, 1] * corner[k, 0]
            record[f, 3 * i] = cx
            record[f, 3 * i + 1] = cy
            record[f, 3 * i + 2] = cz
            nx += cx
            ny += cy
            nz += cz
        offset = nx * corner[0, 0] + ny * corner[0, 1] + nz * corner[0, 2]
        record[f, OFFSET] = offset
        # Embree subtracts the eye in float32 (rounding each corner by its distance from the eye) and
        # multiplies: its error on an edge function scales with the corners' distance times the ray's
        # distance from them
        far = edge = radius = 0.0
        mx = (corner[0, 0] + corner[1, 0] + corner[2, 0]) / 3.0
        my = (corner[0, 1] + corner[1, 1] + corner[2, 1]) / 3.0
        mz = (corner[0, 2] + corner[1, 2] + corner[2, 2]) / 3.0
        for i in range(3):
            j = (i + 1) % 3
            far = max(far, math.sqrt(corner[i, 0] ** 2 + corner[i, 1] ** 2 + corner[i, 2] ** 2))
            edge = max(
                edge,
                math.sqrt(
                    (corner[i, 0] - corner[j, 0]) ** 2
                    + (corner[i, 1] - corner[j, 1]) ** 2
                    + (corner[i, 2] - corner[j, 2]) ** 2
                ),
            )
            radius = max(
                radius, math.sqrt((corner[i, 0] - mx) ** 2 + (corner[i, 1] - my) ** 2 + (corner[i, 2] - mz) ** 2)
            )
        spread[f, 0] = mx
        spread[f, 1] = my
        spread[f, 2] = mz
        spread[f, 3] = ulp * far
        spread[f, 4] = radius + edge
        # t = T / den: Embree's T is its corner (rounded by ~ulp far) times its normal (rounded by ~ulp far edge)
        t_ulp = T_ULPS * 2.0**-24
        record[f, REL_T] = t_ulp * far * (far * edge + edge * edge) / abs(offset) if offset != 0.0 else math.inf
        size = math.sqrt(nx * nx + ny * ny + nz * nz)
        distance = abs(offset) / size if size > 0.0 else 0.0
        plane[f] = distance
        # ---- its projection: what lies nearer than eps along the view axis lies farther than ``reach`` ----
        eps = 0.5 * distance / math.sqrt(reach * reach + 1.0)
        if not distance > 1e-9 * far:  # its plane holds the eye, within rounding: it may be met anywhere
            lo_a = lo_b = -math.inf
            hi_a = hi_b = math.inf
        else:
            lo_a, hi_a, lo_b, hi_b = _projection(corner, 1.0, eps)
            if not record[f, REL_T] < 1.0:  # Embree may see it on the wrong side of the eye: its mirror image too
                la, ha, lb, hb = _projection(corner, -1.0, eps)
                lo_a, hi_a, lo_b, hi_b = min(lo_a, la), max(hi_a, ha), min(lo_b, lb), max(hi_b, hb)
        # ---- the cells of its projection, PAD wider; none when nothing of it lies in front of the eye ----
        x0 = np.floor(lo_a * scale_x + shift_x - PAD)
        x1 = np.floor(hi_a * scale_x + shift_x + PAD)
        y0 = np.floor(hi_b * scale_y + shift_y - PAD)  # scale_y < 0: rows run down the image
        y1 = np.floor(lo_b * scale_y + shift_y + PAD)
        live[f] = lo_a <= hi_a and x1 >= 0.0 and x0 < columns and y1 >= 0.0 and y0 < rows
        if live[f]:
            cells[f, 0] = int(min(max(x0, 0.0), columns - 1.0))
            cells[f, 1] = int(min(max(x1, 0.0), columns - 1.0))
            cells[f, 2] = int(min(max(y0, 0.0), rows - 1.0))
            cells[f, 3] = int(min(max(y1, 0.0), rows - 1.0))
        else:
            cells[f, 0] = cells[f, 1] = cells[f, 2] = cells[f, 3] = 0


@numba.njit(inline="always")
def _projection(corner, side, eps):
    """The bounds ``(a_min, a_max, b_min, b_max)`` on the image plane of the part at ``z >= eps`` of the
    triangle of ``corner`` (3, 3), camera frame, times ``side`` (1, or -1: its mirror image through the eye);
    ``a_min > a_max`` when it has no such part."""
    lo_a = lo_b = math.inf
    hi_a = hi_b = -math.inf
    for i in range(3):
        j = (i + 1) % 3
        zi = side * corner[i, 2]
        zj = side * corner[j, 2]
        if zi >= eps:
            pa = side * corner[i, 0] / zi
            pb = side * corner[i, 1] / zi
            lo_a, hi_a, lo_b, hi_b = min(lo_a, pa), max(hi_a, pa), min(lo_b, pb), max(hi_b, pb)
        if (zi - eps) * (zj - eps) < 0.0:  # the edge crosses z = eps: where, on the image plane
            w = (eps - zi) / (zj - zi)
            pa = side * (corner[i, 0] + w * (corner[j, 0] - corner[i, 0])) / eps
            pb = side * (corner[i, 1] + w * (corner[j, 1] - corner[i, 1])) / eps
            lo_a, hi_a, lo_b, hi_b = min(lo_a, pa), max(hi_a, pa), min(lo_b, pb), max(hi_b, pb)
    return lo_a, hi_a, lo_b, hi_b


@jit
def _fill(cells, live, records, plane, spread, grid, frame, row0, row1):
    """The lists of the cells of rows ``row0..row1 - 1``: ``(start (C+1,) int64, cover (C,) int32, faces (K,)
    int32, errors (K,) float32, nearest (K,) float32)``, C their cells, each face of cells ``cells[f, 0]..
    cells[f, 1]`` x ``cells[f, 2]..cells[f, 3]`` listed where it is not provably hidden, with the bound of
    Embree's error on its edge functions anywhere in the cell and the nearest Embree can place it there. A band
    of rows a call: the bands of a build run on threads side by side.
    grid : columns, rows, the longest list;  frame : scale_x, shift_x, scale_y, shift_y
    """
    columns, rows, longest = grid[0], grid[1], grid[2]
    scale_x, shift_x, scale_y, shift_y = frame[0], frame[1], frame[2], frame[3]
    count = columns * (row1 - row0)
    sizes = np.zeros(count + 1, np.int64)
    for f in range(len(live)):
        if live[f]:
            for gy in range(max(cells[f, 2], row0), min(cells[f, 3] + 1, row1)):
                for gx in range(cells[f, 0], cells[f, 1] + 1):
                    sizes[(gy - row0) * columns + gx + 1] += 1
    first = np.cumsum(sizes)
    every = np.empty(first[-1], np.int32)
    at = first[:-1].copy()
    for f in range(len(live)):
        if live[f]:
            for gy in range(max(cells[f, 2], row0), min(cells[f, 3] + 1, row1)):
                for gx in range(cells[f, 0], cells[f, 1] + 1):
                    c = (gy - row0) * columns + gx
                    every[at[c]] = f
                    at[c] += 1
    # ---- drop what is provably hidden, cap the lists ----
    start = np.zeros(count + 1, np.int64)
    cover = np.full(count, -1, np.int32)
    faces = np.empty(min(len(every), count * (longest + 1)), np.int32)
    errors = np.empty(len(faces), np.float32)
    nearest_at = np.empty(len(faces), np.float32)
    corners = np.empty((4, 2))
    values = np.empty((4, 4))  # a face's edge functions and their sum at the cell's corners (_at_corners)
    dets_c = np.empty(4)  # the covering face's sums there
    kept = 0
    for c in range(count):
        gy = c // columns
        gx = c - gy * columns
        gy += row0
        widest = 0.0  # the longest w = a r + b u + f of the cell's rays
        for q in range(4):
            corners[q, 0] = (gx + (q & 1) * (1.0 + 2e-3) - 1e-3 - shift_x) / scale_x
            corners[q, 1] = (gy + (q >> 1) * (1.0 + 2e-3) - 1e-3 - shift_y) / scale_y
            widest = max(widest, math.sqrt(1.0 + corners[q, 0] ** 2 + corners[q, 1] ** 2))
        ca = 0.5 * (corners[0, 0] + corners[3, 0])
        cb = 0.5 * (corners[0, 1] + corners[3, 1])
        half = 0.5 * math.sqrt((corners[3, 0] - corners[0, 0]) ** 2 + (corners[3, 1] - corners[0, 1]) ** 2)
        nearest = math.inf  # the farthest the best covering face lies along a ray of the cell
        covering = -1  # that face
        for k in range(first[c], first[c + 1]):
            f = every[k]
            # only a face whose projection reaches past the cell on every side can cover it: the cell lies
            # inside its box of cells (clipped to the grid at its borders); most faces span a cell or two
            if (
                (cells[f, 0] < gx or gx == 0)
                and (gx < cells[f, 1] or gx == columns - 1)
                and (cells[f, 2] < gy or gy == 0)
                and (gy < cells[f, 3] or gy == rows - 1)
            ):
                deepest = _covers(records, f, corners)
                if deepest < nearest:
                    nearest, covering = deepest, f
        covering_err = _error(spread, covering, ca, cb, half, widest) if covering >= 0 else 0.0
        if covering >= 0:
            for q in range(4):
                dets_c[q] = _det(records, covering, corners[q, 0], corners[q, 1])
        reach = nearest * widest * 1.01  # no ray of the cell meets the covering face farther than this
        begin = kept
        for k in range(first[c], first[c + 1]):
            f = every[k]
            if plane[f] * (1.0 - records[f, REL_T]) > reach and records[f, REL_T] < 1e-3:
                continue  # hidden: Embree cannot place it nearer than its plane
            err = _error(spread, f, ca, cb, half, widest)
            _at_corners(records, f, corners, values)  # once: every test below reads them
            if _missed(values, err):
                continue  # no ray of the cell meets it: the kernel would pass it by on every one
            if nearest < math.inf and _behind(records, f, values, err, HIDDEN * nearest):
                continue  # hidden: wherever Embree meets it in this cell, it is farther than the covering face
            if (
                f != covering
                and covering >= 0
                and _behind_face(records, f, err, values, covering, covering_err, dets_c)
            ):
                continue  # hidden ray by ray: on every ray of the cell Embree places it behind the covering face
            if kept - begin >= longest:
                cover[c] = LONG_CELL
                break
            # front to back by the nearest Embree can place it in the cell (insertion: a list is short)
            near = _nearest(records, f, values, err)
            at = kept
            while at > begin and nearest_at[at - 1] > near:
                faces[at] = faces[at - 1]
                errors[at] = errors[at - 1]
                nearest_at[at] = nearest_at[at - 1]
                at -= 1
            faces[at] = f
            errors[at] = err
            nearest_at[at] = near
            kept += 1
        if cover[c] == LONG_CELL:
            kept = begin
        elif kept - begin == 1 and _answers_all(records, faces[begin], corners, errors[begin]):
            cover[c] = faces[begin]  # alone and inside it all over the cell: every ray of the cell meets it
        start[c + 1] = kept
    return start, cover, faces[:kept].copy(), errors[:kept].copy(), nearest_at[:kept].copy()


@jit
def _cap(start, cover, faces, errors, nearest_at, longest, most):
    """The lists of ``_fill`` (all bands', one after the other) within ``most`` entries in all: the longest lists
    go to Embree first (their cells marked long)."""
    count = len(cover)
    kept = start[count]
    lengths = np.zeros(longest + 1, np.int64)
    for c in range(count):
        lengths[start[c + 1] - start[c]] += 1
    cap = longest
    total = kept
    while total > most and cap > 0:
        total -= cap * lengths[cap]
        cap -= 1
    if cap == longest:
        return start, cover, faces[:kept].copy(), errors[:kept].copy(), nearest_at[:kept].copy()
    at = 0
    begin = 0
    for c in range(count):
        end = start[c + 1]
        if end - begin > cap:
            cover[c] = LONG_CELL
        else:
            for k in range(begin, end):
                faces[at] = faces[k]
                errors[at] = errors[k]
                nearest_at[at] = nearest_at[k]
                at += 1
        begin = end
        start[c + 1] = at
    return start, cover, faces[:at].copy(), errors[:at].copy(), nearest_at[:at].copy()


@jit
def _first_named(faces, count, offset):
    """The faces of ``faces`` in the order the lists first name them (M,) int64, and each face's number in
    that order plus ``offset`` (count,) int32 (-1: not named)."""
    local = np.full(count, -1, np.int32)
    named = np.empty(min(len(faces), count), np.int64)
    m = 0
    for f in faces:
        if local[f] < 0:
            local[f] = m + offset
            named[m] = f
            m += 1
    return named[:m], local


@numba.njit(inline="always")
def _answers_all(records, f, corners, err):
    """Whether every ray of the cell of ``corners`` meets face ``f`` provably as the kernel requires (inside by
    its margins at every corner, ``visibility._answer``), so that the kernel need not test it ray by ray."""
    sign = 0.0
    for q in range(4):
        a = corners[q, 0]
        b = corners[q, 1]
        u0 = records[f, 0] * a + records[f, 1] * b + records[f, 2]
        u1 = records[f, 3] * a + records[f, 4] * b + records[f, 5]
        u2 = records[f, 6] * a + records[f, 7] * b + records[f, 8]
        det = u0 + u1 + u2
        spread = 3.0 * err
        s = 1.0 if det > 0.0 else -1.0
        if not abs(det) > 2.0 * spread or (sign != 0.0 and s != sign):
            return False
        sign = s
        # inside by the margin at every corner: inside by it all over the cell (u - EDGE |det| is linear)
        margin = EDGE * (abs(det) + 2.0 * spread) + 2.0 * err
        if s * u0 < margin or s * u1 < margin or s * u2 < margin:
            return False
        rel = records[f, REL_T] + spread / abs(det)
        if not (rel < 0.5 and records[f, OFFSET] / det > 0.0):
            return False
    return True


@numba.njit(inline="always")
def _det(records, f, a, b):
    """The sum of face ``f``'s three edge functions at ``(a, b)``, term by term in record order."""
    det = 0.0
    det += records[f, 0] * a
    det += records[f, 1] * b
    det += records[f, 2]
    det += records[f, 3] * a
    det += records[f, 4] * b
    det += records[f, 5]
    det += records[f, 6] * a
    det += records[f, 7] * b
    det += records[f, 8]
    return det


@numba.njit(inline="always")
def _at_corners(records, f, corners, values):
    """Face ``f``'s three edge functions at the four ``corners`` of a cell and their sum term by term in record
    order (:func:`_det`) into ``values`` (4, 4): computed once for all of a cell's tests of the face."""
    for q in range(4):
        a = corners[q, 0]
        b = corners[q, 1]
        values[q, 0] = records[f, 0] * a + records[f, 1] * b + records[f, 2]
        values[q, 1] = records[f, 3] * a + records[f, 4] * b + records[f, 5]
        values[q, 2] = records[f, 6] * a + records[f, 7] * b + records[f, 8]
        values[q, 3] = _det(records, f, a, b)


@numba.njit(inline="always")
def _nearest(records, f, values, err):
    """The nearest depth at which Embree can place face ``f`` on a ray of the cell whose corners give it
    ``values`` (:func:`_at_corners`; its edge functions' error ``err``), rounded down to float32; -infinity
    where it cannot be bounded (grazing somewhere in the cell, its depth's sign uncertain)."""
    sign = 0.0
    low = math.inf
    for q in range(4):
        det = values[q, 3]
        s = 1.0 if det > 0.0 else -1.0
        if not abs(det) > 6.0 * err or (sign != 0.0 and s != sign):
            return -math.inf
        sign = s
        rel = records[f, REL_T] + 3.0 * err / abs(det) + 1e-9
        z = records[f, OFFSET] / det
        if not (rel < 0.5 and z > 0.0):
            return -math.inf
        low = min(low, z * (1.0 - rel))
    # 1/z is linear over the cell and |det| too: the extremes lie at the corners; float32 rounds within 6e-8
    return np.float32(low * (1.0 - 1e-6))


@numba.njit(inline="always")
def _behind(records, f, values, err, depth):
    """Whether Embree, meeting face ``f`` anywhere in the cell whose corners give it ``values`` (its edge
    functions' error ``err``), places it deeper than ``depth`` or behind the eye: its plane's depth over the
    cell (extreme at the corners: its inverse is linear) with the error of t that the kernel allows."""
    sign = 0.0
    behind = False
    for q in range(4):
        det = values[q, 3]
        s = 1.0 if det > 0.0 else -1.0
        if not abs(det) > 6.0 * err or (sign != 0.0 and s != sign):
            return False  # grazing somewhere in the cell
        sign = s
        rel = records[f, REL_T] + 3.0 * err / abs(det)
        z = records[f, OFFSET] / det
        if not rel < 0.5 or not (z < 0.0 or z * (1.0 - rel) > depth):
            return False
        if q > 0 and (z < 0.0) != behind:
            return False
        behind = z < 0.0
    return True


@numba.njit(inline="always")
def _error(spread, f, ca, cb, half, widest):
    """The bound of Embree's error on face ``f``'s edge functions anywhere in a cell (centre ``(ca, cb)`` on the
    image plane, ``half`` its half diagonal, ``widest`` the longest ``|w|`` of its rays)."""
    # the ray's distance from the face's centre, anywhere in the cell, times |w|
    x, y, z = spread[f, 0], spread[f, 1], spread[f, 2]
    cx = y - z * cb
    cy = z * ca - x
    cz = x * cb - y * ca
    distance = math.sqrt(cx * cx + cy * cy + cz * cz) + math.sqrt(x * x + y * y + z * z) * half
    return spread[f, 3] * (distance + spread[f, 4] * widest) * 1.001


@numba.njit(inline="always")
def _missed(values, err):
    """Whether ``visibility.classify`` finds a face certainly missed by every ray of the cell whose corners give
    it ``values`` (edge error ``err``): one edge function below ``-err`` and another above ``err`` all over the
    cell, which holds where it holds at the four corners (they are linear)."""
    below0 = below1 = below2 = above0 = above1 = above2 = True  # scalars: an array a call costs an allocation
    bound = 1.000001 * err  # a margin for the rounding of u at a ray inside
    for q in range(4):
        u0, u1, u2 = values[q, 0], values[q, 1], values[q, 2]
        below0 &= u0 < -bound
        below1 &= u1 < -bound
        below2 &= u2 < -bound
        above0 &= u0 > bound
        above1 &= u1 > bound
        above2 &= u2 > bound
    return (below0 or below1 or below2) and (above0 or above1 or above2)


@numba.njit(inline="always")
def _behind_face(records, f, err, values, c, err_c, dets_c):
    """Whether, on every ray of the cell, the nearest Embree can place face ``f`` (edge error ``err``, its ``values``
    at the cell's corners) lies deeper than the farthest it can place face ``c`` (``err_c``, its sums at the
    corners ``dets_c``), with the kernel's bound of the error of t (``visibility.classify``'s). The ratio of the
    two depths is a ratio of linear functions over the cell (``OFFSET / det`` each), so its least is at a
    corner, as is each bound's largest (``1 / |det|`` is convex where ``det`` keeps its sign)."""
    sign_f = sign_c = 0.0
    ratio = math.inf
    rel_f = rel_c = 0.0
    for q in range(4):
        det_f = values[q, 3]
        det_c = dets_c[q]
        s_f = 1.0 if det_f > 0.0 else -1.0
        s_c = 1.0 if det_c > 0.0 else -1.0
        if not abs(det_f) > 6.0 * err or (sign_f != 0.0 and s_f != sign_f):
            return False  # grazing somewhere in the cell
        if not abs(det_c) > 6.0 * err_c or (sign_c != 0.0 and s_c != sign_c):
            return False
        sign_f, sign_c = s_f, s_c
        z_f = records[f, OFFSET] / det_f
        z_c = records[c, OFFSET] / det_c
        if not (z_f > 0.0 and z_c > 0.0):
            return False
        ratio = min(ratio, z_f / z_c)
        rel_f = max(rel_f, records[f, REL_T] + 3.0 * err / abs(det_f) + 1e-9)
        rel_c = max(rel_c, records[c, REL_T] + 3.0 * err_c / abs(det_c) + 1e-9)
    return rel_f < 0.5 and ratio * (1.0 - rel_f) > (1.0 + rel_c) * (1.0 + 1e-6)


@numba.njit(inline="always")
def _covers(records, f, corners):
    """How deep face ``f`` lies at most, where it covers the whole cell of the four ``corners`` (points
    ``(a, b)`` of the image plane): its largest depth over the cell; infinity where it does not cover it."""
    deepest = 0.0
    sign = 0.0
    for q in range(4):
        a = corners[q, 0]
        b = corners[q, 1]
        u0 = records[f, 0] * a + records[f, 1] * b + records[f, 2]
        u1 = records[f, 3] * a + records[f, 4] * b + records[f, 5]
        u2 = records[f, 6] * a + records[f, 7] * b + records[f, 8]
        det = u0 + u1 + u2
        if det == 0.0:
            return math.inf
        s = 1.0 if det > 0.0 else -1.0
        if sign != 0.0 and s != sign:
            return math.inf
        sign = s
        # inside at every corner: inside all over the (convex) cell
        margin = 1e-9 * abs(det)
        if s * u0 <= margin or s * u1 <= margin or s * u2 <= margin:
            return math.inf
        depth = records[f, OFFSET] / det
        if not depth > 0.0:
            return math.inf
        deepest = max(deepest, depth)
    return deepest
