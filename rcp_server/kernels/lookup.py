"""The image-space method's lookup, fused and compiled: the plain render read where each pixel's displaced
target projects (``imagespace.py`` has the conventions and the numpy form; the tests check they agree).
"""

from __future__ import annotations

import math

import numba

from .jit import jit

EDGE_CLAMP, EDGE_WRAP, EDGE_MIRROR = 0, 1, 2  # the kernel's codes for EDGES, in order


@numba.njit(inline="always")
def _edge(k, n, edge):
    if edge == EDGE_CLAMP:
        return min(max(k, 0), n - 1)
    k %= n if edge == EDGE_WRAP else 2 * n  # Python's modulo: never negative
    return 2 * n - 1 - k if k >= n else k


@jit
def look_up(v_p, moves, plane, edge, plain, out):
    """``imagespace.lookup_coords`` and ``imagespace.bilinear`` fused, for one region and every recorded channel.

    v_p : (n, 3) float64 displacement per pixel of the region (not read unless ``moves``)
    plane : a bundles.ImagePlane (the frame camera's plane and the region);  edge : EDGE_*
    plain : bundles.Channels, the plain render of the full image, row-major (W*H, ...) float32; all but
    color may be dummies. out : bundles.Channels of the region's n pixels, each written only when the
    matching plain channel is full-size; out.direction is renormalised (a bilinear mix of unit vectors
    is shorter than one).
    """
    basis, tan_half, aspect = plane.basis, plane.tan_half, plane.aspect
    full_width, full_height = plane.full_width, plane.full_height
    x0, y0, width = plane.x0, plane.y0, plane.width
    color, depth, normal, direction = plain.color, plain.depth, plain.normal, plain.direction
    out_color, out_depth, out_normal, out_direction = out.color, out.depth, out.normal, out.direction
    n_pix = out_color.shape[0]
    n_full = full_width * full_height
    has_depth = depth.shape[0] == n_full
    has_normal = normal.shape[0] == n_full
    has_direction = direction.shape[0] == n_full
    mixed = (plain.geometric, plain.albedo, plain.uv, plain.position)  # the other channels, bilinear too
    mixed_out = (out.geometric, out.albedo, out.uv, out.position)
    has_object = plain.object.shape[0] == n_full
    has_material = plain.material.shape[0] == n_full
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
            for k in range(4):
                if mixed[k].shape[0] == n_full:
                    src, dst = mixed[k], mixed_out[k]
                    for q in range(dst.shape[1]):
                        dst[pix, q] = w00 * src[a0, q] + w01 * src[a1, q] + w10 * src[b0, q] + w11 * src[b1, q]
            # an index does not mix: the nearest of the four
            nearest = a0 if fx < 0.5 and fy < 0.5 else (a1 if fy < 0.5 else (b0 if fx < 0.5 else b1))
            if has_object:
                out.object[pix] = plain.object[nearest]
            if has_material:
                out.material[pix] = plain.material[nearest]
