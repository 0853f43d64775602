"""The image-space method's lookup, fused and compiled: the plain render read where each pixel's displaced
target projects (``imagespace.py`` has the conventions and the numpy form; the tests check they agree).
"""

from __future__ import annotations

import math

import numba

from .jit import jit
from .projection import EQUIRECT, centre_frame, locate, target_offset, to_pixel

EDGE_CLAMP, EDGE_WRAP, EDGE_MIRROR = 0, 1, 2  # the kernel's codes for EDGES, in order


@numba.njit(inline="always")
def _edge(k, n, edge):
    if edge == EDGE_CLAMP:
        return min(max(k, 0), n - 1)
    k %= n if edge == EDGE_WRAP else 2 * n  # Python's modulo: never negative
    return 2 * n - 1 - k if k >= n else k


@numba.njit(inline="always")
def _sphere(c, r, width, height):
    """Pixel ``(c, r)`` of a panorama, one step off it at most: longitude wraps, a row past a pole is the row on
    its other side, half a turn around."""
    if r < 0:
        r = -1 - r
        c += width // 2
    elif r >= height:
        r = 2 * height - 1 - r
        c += width // 2
    return c % width, r


@jit
def look_up(v_p, moves, plane, edge, plain, out):
    """``imagespace.lookup_coords`` and ``imagespace.bilinear`` fused, for one region and every recorded channel.

    v_p : (n, 3) float64 displacement per pixel of the region (not read unless ``moves``)
    plane : a bundles.ImagePlane (the projection and the region);  edge : EDGE_*, how an image plane is read
    off its edges (a panorama has none: longitude wraps and the poles mirror). Each eye of a stereo painting
    reads its own image. plain : bundles.Channels, the plain render of the full painting, row-major (W*H, ...)
    float32; all but color may be dummies. out : bundles.Channels of the region's n pixels, each written only
    when the matching plain channel is full-size; out.direction is renormalised (a bilinear mix of unit
    vectors is shorter than one).
    """
    full_width, full_height = plane.full_width, plane.full_height
    eye_w, eye_h = plane.eye_width, plane.eye_height
    x0, y0, width = plane.x0, plane.y0, plane.width
    sphere = plane.projection == EQUIRECT
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
    rows = n_pix // width
    span_x = float(eye_w) if edge == EDGE_WRAP else 2.0 * eye_w
    span_y = float(eye_h) if edge == EDGE_WRAP else 2.0 * eye_h
    for row in range(rows):
        j = y0 + row
        for col in range(width):
            pix = row * width + col
            side, li, lj = locate(plane, x0 + col, j)
            x_off = x0 + col - li  # where the eye's image starts in the painting
            y_off = j - lj
            # continuous coordinates in the eye's image, centres on the integers
            x = float(li)
            y = float(lj)
            if moves:
                _, _, _, _, _, _, fx, fy, fz = centre_frame(plane, li, lj)
                if plane.projection != EQUIRECT:
                    fx, fy, fz = target_offset(plane, li + 0.5, lj + 0.5)
                # the projection of P_p' minus that of P_p: V_p = 0 stays exactly on the pixel
                ax, ay, ok_a = to_pixel(plane, 0, fx + v_p[pix, 0], fy + v_p[pix, 1], fz + v_p[pix, 2])
                bx, by, ok_b = to_pixel(plane, 0, fx, fy, fz)
                if ok_a and ok_b:
                    dx = ax - bx
                    if sphere:  # the shorter way round
                        dx = (dx + 0.5 * eye_w) % eye_w - 0.5 * eye_w
                    x += dx
                    y += ay - by
            if 0.0 <= x < eye_w - 1 and 0.0 <= y < eye_h - 1:  # on screen, all four neighbours too: most pixels
                c0 = int(x)
                r0 = int(y)
                fx = x - c0
                fy = y - r0
                c1 = c0 + 1
                r1 = r0 + 1
                c2 = c0
                c3 = c1
            elif sphere:
                x %= eye_w
                y = min(max(y, -0.5), eye_h - 0.5)
                fx0 = math.floor(x)
                fy0 = math.floor(y)
                fx = x - fx0
                fy = y - fy0
                c0, r0 = _sphere(int(fx0), int(fy0), eye_w, eye_h)
                c1, _ = _sphere(int(fx0) + 1, int(fy0), eye_w, eye_h)
                c2, r1 = _sphere(int(fx0), int(fy0) + 1, eye_w, eye_h)
                c3, _ = _sphere(int(fx0) + 1, int(fy0) + 1, eye_w, eye_h)
            else:
                # ---- into a range whose integer neighbours fit, then the four pixels by the edge mode ----
                if edge == EDGE_CLAMP:
                    x = min(max(x, -1.0), float(eye_w))
                    y = min(max(y, -1.0), float(eye_h))
                else:
                    x %= span_x
                    y %= span_y
                fx0 = math.floor(x)
                fy0 = math.floor(y)
                fx = x - fx0
                fy = y - fy0
                c0 = _edge(int(fx0), eye_w, edge)
                c1 = _edge(int(fx0) + 1, eye_w, edge)
                r0 = _edge(int(fy0), eye_h, edge)
                r1 = _edge(int(fy0) + 1, eye_h, edge)
                c2 = c0
                c3 = c1
            # c2, c3: the columns of the lower two neighbours (not those of the upper two across a pole)
            a0 = (y_off + r0) * full_width + x_off + c0
            a1 = (y_off + r0) * full_width + x_off + c1
            b0 = (y_off + r1) * full_width + x_off + c2
            b1 = (y_off + r1) * full_width + x_off + c3
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
