"""The image-space variant (paper section 6, the game-engine route): with ``V_e = 0`` a displaced target
``P_p' = P_p + V_p`` is seen along a primary ray of the same eye, so instead of tracing it we look up the
plain render where that ray crosses the image plane.

Pixel coordinates here are continuous, with pixel centres on the integers: pixel ``(i, j)`` covers
``[i - 0.5, i + 0.5) x [j - 0.5, j + 0.5)`` (so ``x = s W - 0.5``, ``y = t H - 0.5`` with ``s, t`` the
texture coordinates of ``camera.py``). A lookup is bilinear between the four nearest pixel centres.

Off screen, an integer pixel index ``k`` of a row of ``n`` pixels is mapped back by the edge mode:

* ``clamp``: ``min(max(k, 0), n - 1)`` (the edge pixel repeats: bars of color);
* ``wrap``: ``k mod n`` (the opposite edge: a seam where the two edges differ);
* ``mirror``: ``k mod 2n`` reflected, ``2n - 1 - k`` for ``k >= n`` (the edge pixel repeats once,
  then the image runs backwards: the paper's choice, and the default).

A pixel whose displaced target is not in front of the eye (``(P_p' - eye) . f <= 0``: it has no
projection) or whose offset is not finite keeps its own plain value. :func:`look_up` is the compiled
pass the painting runs; :func:`lookup_coords` and :func:`bilinear` are its plain numpy form (the tests
check that they agree).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .camera import Camera, Region
from .params import EDGES


def lookup_coords(v_p: np.ndarray, camera: Camera, region: Region) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each pixel's displaced target ``P_p' = P_p + V_p`` projects on the frame camera's image plane.

    v_p : (n, 3) float64 target displacement of each pixel of ``region`` (at its centre), scene units.
    Returns ``x, y`` (n,) float64 continuous pixel coordinates of the full image, and ``ok`` (n,) bool:
    False where ``P_p'`` is not in front of the eye (it cannot be projected) or a coordinate is not finite;
    there ``x, y`` are the pixel's own centre, so that pixel keeps its own plain value.

    ``V_p = 0`` gives exactly the pixel's own integer coordinates: the offset is computed, not the position.
    """
    r, u, f = camera.basis()
    pitch = camera.pixel_pitch(region.full_height)
    i, j = region.pixel_coords()
    tan_half = camera.half_height()
    aspect = region.full_width / region.full_height
    # the pixel centre on the plane: eye + f + sx r + ty u
    sx = (2.0 * (i + 0.5) / region.full_width - 1.0) * aspect * tan_half
    ty = (1.0 - 2.0 * (j + 0.5) / region.full_height) * tan_half
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # non-finite input: refused below
        vr, vu, vf = v_p @ r, v_p @ u, v_p @ f
        ahead = 1.0 + vf  # P_p' - eye along f: the plane is at 1
        # the projection of P_p' minus that of P_p, in pixels (t, and so y, runs down)
        dx = (vr - sx * vf) / ahead / pitch
        dy = -(vu - ty * vf) / ahead / pitch
    ok = (ahead > 0.0) & np.isfinite(dx) & np.isfinite(dy)
    x = i + np.where(ok, dx, 0.0)
    y = j + np.where(ok, dy, 0.0)
    return x, y, ok


def _reduce(coord: np.ndarray, n: int, edge: str) -> np.ndarray:
    """Bring a coordinate into a range where its integer neighbours fit int64, without changing the lookup:
    clamp is constant beyond [0, n - 1], wrap and mirror are periodic with period n and 2n."""
    if edge == "clamp":
        return np.clip(coord, -1.0, float(n))
    if edge == "wrap":
        return np.mod(coord, float(n))
    return np.mod(coord, 2.0 * n)


def edge_index(k: np.ndarray, n: int, edge: str) -> np.ndarray:
    """Integer pixel indices ``k`` (any int64) mapped into ``[0, n)`` by the edge mode (module docstring)."""
    if edge == "clamp":
        return np.clip(k, 0, n - 1)
    if edge == "wrap":
        return np.mod(k, n)
    if edge == "mirror":
        k = np.mod(k, 2 * n)
        return np.where(k >= n, 2 * n - 1 - k, k)
    raise ValueError(f"unknown edge mode {edge!r}; choose one of {', '.join(EDGES)}")


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray, edge: str) -> np.ndarray:
    """Bilinear lookup of ``image`` (h, w) or (h, w, c) at continuous pixel coordinates ``x, y`` ((n,)
    float64, centres on the integers), off-screen indices mapped by ``edge``. Returns (n,) or (n, c) in
    float64; an integer ``(x, y)`` returns that pixel's value exactly."""
    h, w = image.shape[:2]
    x = _reduce(x, w, edge)
    y = _reduce(y, h, edge)
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = x - x0
    fy = y - y0
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    c0, c1 = edge_index(x0, w, edge), edge_index(x0 + 1, w, edge)
    r0, r1 = edge_index(y0, h, edge), edge_index(y0 + 1, h, edge)
    if image.ndim == 3:
        fx = fx[:, None]
        fy = fy[:, None]
    top = image[r0, c0] * (1.0 - fx) + image[r0, c1] * fx
    bottom = image[r1, c0] * (1.0 - fx) + image[r1, c1] * fx
    return top * (1.0 - fy) + bottom * fy


EDGE_CLAMP, EDGE_WRAP, EDGE_MIRROR = 0, 1, 2  # the kernel's codes for EDGES, in order

_jit = numba.njit(nogil=True, cache=True, error_model="numpy")


@numba.njit(inline="always")
def _edge(k, n, edge):
    if edge == EDGE_CLAMP:
        return min(max(k, 0), n - 1)
    k %= n if edge == EDGE_WRAP else 2 * n  # Python's modulo: never negative
    return 2 * n - 1 - k if k >= n else k


@_jit
def look_up(
    v_p,
    moves,
    basis,
    tan_half,
    aspect,
    full_width,
    full_height,
    x0,
    y0,
    width,
    edge,
    color,
    depth,
    normal,
    direction,
    out_color,
    out_depth,
    out_normal,
    out_direction,
):
    """:func:`lookup_coords` and :func:`bilinear` fused, for one region and every recorded channel.

    v_p : (n, 3) float64 displacement per pixel of the region (not read unless ``moves``)
    basis : (3, 3) rows r, u, f;  tan_half, aspect : as in kernels.cast_rays;  edge : EDGE_*
    color, depth, normal, direction : the plain render of the full image, row-major (W*H, ...) float32;
    the last three may be dummies. out_* : (n, ...) float32, written only when the matching input is
    full-size; out_direction is renormalised (a bilinear mix of unit vectors is shorter than one).
    """
    n_pix = out_color.shape[0]
    n_full = full_width * full_height
    has_depth = depth.shape[0] == n_full
    has_normal = normal.shape[0] == n_full
    has_direction = direction.shape[0] == n_full
    inv_pitch = full_height / (2.0 * tan_half)
    last_x = float(full_width - 1)
    last_y = float(full_height - 1)
    rows = n_pix // width
    span_x = float(full_width) if edge == EDGE_WRAP else 2.0 * full_width
    span_y = float(full_height) if edge == EDGE_WRAP else 2.0 * full_height
    for row in range(rows):
        j = y0 + row
        ty = (1.0 - 2.0 * (j + 0.5) / full_height) * tan_half
        for col in range(width):
            pix = row * width + col
            i = x0 + col
            x = float(i)
            y = float(j)
            if moves:
                sx = (2.0 * (i + 0.5) / full_width - 1.0) * aspect * tan_half
                vr = v_p[pix, 0] * basis[0, 0] + v_p[pix, 1] * basis[0, 1] + v_p[pix, 2] * basis[0, 2]
                vu = v_p[pix, 0] * basis[1, 0] + v_p[pix, 1] * basis[1, 1] + v_p[pix, 2] * basis[1, 2]
                vf = v_p[pix, 0] * basis[2, 0] + v_p[pix, 1] * basis[2, 1] + v_p[pix, 2] * basis[2, 2]
                ahead = 1.0 + vf
                if ahead > 0.0:
                    scale = inv_pitch / ahead
                    dx = (vr - sx * vf) * scale
                    dy = (ty * vf - vu) * scale
                    if math.isfinite(dx) and math.isfinite(dy):
                        x += dx
                        y += dy
            if 0.0 <= x < last_x and 0.0 <= y < last_y:  # on screen, all four neighbours too: most pixels
                c0 = int(x)
                r0 = int(y)
                fx = x - c0
                fy = y - r0
                c1 = c0 + 1
                r1 = r0 + 1
            else:
                # ---- into a range whose integer neighbours fit, then the four pixels by the edge mode ----
                if edge == EDGE_CLAMP:
                    x = min(max(x, -1.0), float(full_width))
                    y = min(max(y, -1.0), float(full_height))
                else:
                    x %= span_x
                    y %= span_y
                fx0 = math.floor(x)
                fy0 = math.floor(y)
                fx = x - fx0
                fy = y - fy0
                c0 = _edge(int(fx0), full_width, edge)
                c1 = _edge(int(fx0) + 1, full_width, edge)
                r0 = _edge(int(fy0), full_height, edge)
                r1 = _edge(int(fy0) + 1, full_height, edge)
            a0 = r0 * full_width + c0
            a1 = r0 * full_width + c1
            b0 = r1 * full_width + c0
            b1 = r1 * full_width + c1
            w00 = (1.0 - fx) * (1.0 - fy)
            w01 = fx * (1.0 - fy)
            w10 = (1.0 - fx) * fy
            w11 = fx * fy
            for q in range(3):
                out_color[pix, q] = w00 * color[a0, q] + w01 * color[a1, q] + w10 * color[b0, q] + w11 * color[b1, q]
            if has_depth:
                out_depth[pix] = w00 * depth[a0] + w01 * depth[a1] + w10 * depth[b0] + w11 * depth[b1]
            if has_normal:
                for q in range(3):
                    out_normal[pix, q] = (
                        w00 * normal[a0, q] + w01 * normal[a1, q] + w10 * normal[b0, q] + w11 * normal[b1, q]
                    )
            if has_direction:
                dx = w00 * direction[a0, 0] + w01 * direction[a1, 0] + w10 * direction[b0, 0] + w11 * direction[b1, 0]
                dy = w00 * direction[a0, 1] + w01 * direction[a1, 1] + w10 * direction[b0, 1] + w11 * direction[b1, 1]
                dz = w00 * direction[a0, 2] + w01 * direction[a1, 2] + w10 * direction[b0, 2] + w11 * direction[b1, 2]
                length = math.sqrt(dx * dx + dy * dy + dz * dz)
                inv = 1.0 / length if length > 0.0 else 0.0
                out_direction[pix, 0] = dx * inv
                out_direction[pix, 1] = dy * inv
                out_direction[pix, 2] = dz * inv
