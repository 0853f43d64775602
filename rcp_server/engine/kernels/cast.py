"""Camera assignment, fused and compiled: the previous iteration's data -> per-sample rays.

``cast_rays`` builds every sample's ray with the built-in mappings' displacement fields fused in
(``fill_field``, which the image-space method also runs alone). It chooses between two kernels, each compiled
at its first use: ``cast_flat``, one pass a row for the common case (an eye at rest on a flat image plane, one
sample a pixel: a walk's frames, a painting's), and ``cast_general`` for everything else; both give the same
bits where both apply. ``tests/engine/test_cast.py`` holds their numpy reference.
"""

from __future__ import annotations

import math

import numpy as np

from .jit import jit
from .projection import EQUIRECT, MONO, centre_frame, locate, target_offset, tile_pixel

# how cast_rays gets a pixel's displacement field D: the built-in mappings fused, or a field given
FIELD_ZERO, FIELD_COLOR, FIELD_DEPTH, FIELD_NORMAL, FIELD_GIVEN = 0, 1, 2, 3, 4


@jit
def fill_field(field, plane, previous, z0, noise, noise_scale, pixels, out):
    """``field.scale * (D + noise_scale * noise)`` for the listed pixels into out (n, 3) float64; see
    mappings.py for D. The rows of pixels not listed are left as they are.

    field : a bundles.Field;  plane : a bundles.ImagePlane of the tile (each pixel's local frame
    ``r_ij, u_ij, f_ij``, ``projection.centre_frame``);  previous : bundles.Channels, I_{n-1} per pixel
    (dummies where the mapping does not read them);  z0 : focus depth;  noise : (n, 3) float32;
    pixels : (m,) int64 indices of the pixels to fill.
    One loop per kind (a branch per pixel costs more than the field itself). Non-finite values move nothing.
    """
    if field.kind == FIELD_ZERO:
        for pix in pixels:
            out[pix, 0] = out[pix, 1] = out[pix, 2] = 0.0
        return
    if field.kind == FIELD_COLOR or field.kind == FIELD_DEPTH:
        rx, ry, rz, ux, uy, uz, fx, fy, fz = centre_frame(plane, 0, 0)  # the same everywhere on a plane
        sphere = plane.projection == EQUIRECT
        for pix in pixels:
            if sphere:
                i, j = tile_pixel(plane, pix)
                _, i, j = locate(plane, i, j)
                rx, ry, rz, ux, uy, uz, fx, fy, fz = centre_frame(plane, i, j)
            k = abs(previous.depth[pix] - z0) if field.kind == FIELD_DEPTH else 1.0
            a = k * (2.0 * previous.color[pix, 0] - 1.0)
            b = k * (2.0 * previous.color[pix, 1] - 1.0)
            c = k * (2.0 * previous.color[pix, 2] - 1.0)
            out[pix, 0] = a * rx + b * ux + c * fx
            out[pix, 1] = a * ry + b * uy + c * fy
            out[pix, 2] = a * rz + b * uz + c * fz
    elif field.kind == FIELD_NORMAL:
        d, nrm = previous.direction, previous.normal
        for pix in pixels:
            out[pix, 0] = d[pix, 1] * nrm[pix, 2] - d[pix, 2] * nrm[pix, 1]
            out[pix, 1] = d[pix, 2] * nrm[pix, 0] - d[pix, 0] * nrm[pix, 2]
            out[pix, 2] = d[pix, 0] * nrm[pix, 1] - d[pix, 1] * nrm[pix, 0]
    else:
        for pix in pixels:
            for q in range(3):
                out[pix, q] = field.given[pix, q]
    scale = field.scale
    for pix in pixels:
        for q in range(3):
            v = scale * (out[pix, q] + noise_scale * noise[pix, q]) if noise_scale != 0.0 else scale * out[pix, q]
            out[pix, q] = v if math.isfinite(v) else 0.0


def cast_rays(
    eye,
    plane,
    xi,
    eta,
    previous,
    z0,
    target,
    eye_field,
    noise,
    noise_scale,
    pixels,
    v_p,
    v_e,
    origins,
    directions,
    write_origins,
) -> int:
    """Per-pixel cameras for every sample: camera assignment fused with the mapping. Returns the number
    of rays that came out non-finite (a NaN or infinite input), so the caller masks only when needed.

    eye : (3,) float64 the camera's;  plane : a bundles.ImagePlane (the projection and the tile, pixels row-major)
    xi, eta : (n, spp) float64 sub-pixel offsets of each sample (not read at 1 spp: the centre)
    previous : bundles.Channels, I_{n-1} per pixel (dummies where the mapping does not read them)
    target, eye_field : bundles.Field of V_p (scale lambda_p * p) and of V_e (scale lambda_e)
    noise : (n, 3) world-space random vectors, added to both fields times noise_scale
    pixels : (m,) int64 the pixels to cast, ascending: sample k of the m-th listed pixel is ray m * spp + k
    v_p, v_e : (n, 3) float64 scratch for the displacements, owned by the caller (a large allocation inside a
    kernel costs more than the whole pass); a field of kind FIELD_ZERO is not written, nor is any by the one pass
    of an eye at rest (:func:`cast_flat`, which keeps the field in registers)
    origins, directions : (n*spp, 3) float32 out (the first m*spp rows): P_e' = eye_ij + V_e, unit direction to
    P_p' = P_p(s, t) + V_p with eye_ij and P_p as in camera.py. A non-finite displacement moves nothing.
    write_origins : False when the eyes do not move and origins already hold the eye (saves a pass of writes)
    """
    count = len(pixels)
    plain = target.kind in (FIELD_ZERO, FIELD_COLOR, FIELD_DEPTH) and eye_field.kind == FIELD_ZERO
    flat = plane.projection != EQUIRECT and plane.layout == MONO
    every = count > 0 and pixels[0] == 0 and pixels[-1] == count - 1  # they ascend: all of them, in order
    if plain and flat and every and xi.shape[1] == 1 and noise_scale == 0.0:  # a walk's, a painting's
        return int(cast_flat(eye, plane, previous, z0, target, count, origins, directions, write_origins))
    return int(
        cast_general(
            eye=eye,
            plane=plane,
            xi=xi,
            eta=eta,
            previous=previous,
            z0=z0,
            target=target,
            eye_field=eye_field,
            noise=noise,
            noise_scale=noise_scale,
            pixels=pixels,
            v_p=v_p,
            v_e=v_e,
            origins=origins,
            directions=directions,
            write_origins=write_origins,
        )
    )


@jit
def cast_general(
    eye,
    plane,
    xi,
    eta,
    previous,
    z0,
    target,
    eye_field,
    noise,
    noise_scale,
    pixels,
    v_p,
    v_e,
    origins,
    directions,
    write_origins,
):
    """:func:`cast_rays` in general, any projection, samples, fields and list of pixels (arguments as its)."""
    spp = xi.shape[1]
    # what does not move is neither filled nor read: at this size every pass over memory counts
    targets_move = target.kind != FIELD_ZERO
    eyes_move = eye_field.kind != FIELD_ZERO
    if targets_move:
        fill_field(target, plane, previous, z0, noise, noise_scale, pixels, v_p)
    if eyes_move:
        fill_field(eye_field, plane, previous, z0, noise, noise_scale, pixels, v_e)
    sphere = plane.projection == EQUIRECT
    half_ipd = plane.half_ipd
    width = plane.width
    px = py = pz = 0.0
    bad = 0
    row = 0
    row_end = -1  # the first pixel past the current row
    j = 0
    for m in range(len(pixels)):
        pix = pixels[m]
        if pix >= row_end:  # pixels ascend: a division once a row, not once a pixel (it costs as much as a ray)
            row = pix // width
            row_end = (row + 1) * width
            j = plane.y0 + row
        side, i, jj = locate(plane, plane.x0 + pix - row * width, j)
        # the pixel's own camera: its eye, and at one sample its centre's target offset (f_ij on the sphere)
        ex = eye[0]
        ey = eye[1]
        ez = eye[2]
        cx = cy = cz = 0.0
        if sphere or side != 0:
            rx, ry, rz, _, _, _, cx, cy, cz = centre_frame(plane, i, jj)
            ex += side * half_ipd * rx
            ey += side * half_ipd * ry
            ez += side * half_ipd * rz
        if targets_move:
            px = v_p[pix, 0]
            py = v_p[pix, 1]
            pz = v_p[pix, 2]
        ox = ex
        oy = ey
        oz = ez
        if eyes_move:
            ox += v_e[pix, 0]
            oy += v_e[pix, 1]
            oz += v_e[pix, 2]
        for k in range(spp):
            # one sample sits at the pixel centre (MISSION.md); only jittered samples read their offsets
            if spp == 1 and sphere:
                tx, ty, tz = cx, cy, cz
            elif spp == 1:
                tx, ty, tz = target_offset(plane, i + 0.5, jj + 0.5)
            else:
                tx, ty, tz = target_offset(plane, i + xi[pix, k], jj + eta[pix, k])
            dx = ex + tx + px - ox
            dy = ey + ty + py - oy
            dz = ez + tz + pz - oz
            norm2 = dx * dx + dy * dy + dz * dz
            if norm2 > 0.0 and norm2 < math.inf:
                inv = 1.0 / math.sqrt(norm2)
            else:  # eye on its target, or a non-finite input: a NaN ray, which misses
                inv = math.nan
                bad += 1
            s = m * spp + k
            if write_origins:
                origins[s, 0] = ox
                origins[s, 1] = oy
                origins[s, 2] = oz
            directions[s, 0] = dx * inv
            directions[s, 1] = dy * inv
            directions[s, 2] = dz * inv
    return bad


@jit
def cast_flat(eye, plane, previous, z0, target, count, origins, directions, write_origins):
    """:func:`cast_rays` of the tile's first ``count`` pixels (all of them, in order) seen by one eye at rest on a
    flat image plane, one sample a pixel at its centre, the target moved by the colour or depth field or not at
    all, without noise: the same arithmetic, in one pass a row without a branch (the compiler runs several pixels
    at once), the field fused in, and what is the same along a column or a row computed once there (the target
    offset is a column's part plus a row's part, added in the order of ``target_offset``)."""
    rx, ry, rz, ux, uy, uz, fx, fy, fz = centre_frame(plane, 0, 0)
    b = plane.basis
    width = plane.width
    columns = np.empty((3, width))  # b_f + s_x b_r of each column of the tile
    for c in range(width):
        sx = ((plane.x0 + c + 0.5) * (2.0 / plane.eye_width) - 1.0) * (plane.aspect * plane.tan_half)
        columns[0, c] = b[2, 0] + sx * b[0, 0]
        columns[1, c] = b[2, 1] + sx * b[0, 1]
        columns[2, c] = b[2, 2] + sx * b[0, 2]
    ex = eye[0]
    ey = eye[1]
    ez = eye[2]
    if write_origins:
        for m in range(count):
            origins[m, 0] = ex
            origins[m, 1] = ey
            origins[m, 2] = ez
    kind = target.kind
    scale = target.scale
    color = previous.color
    depth = previous.depth
    bad = 0
    d = np.empty((4, width))  # a row's unnormalised directions and their squared lengths
    for row in range((count + width - 1) // width):
        ty = (1.0 - (plane.y0 + row + 0.5) * (2.0 / plane.eye_height)) * plane.tan_half
        row_x = ty * b[1, 0]
        row_y = ty * b[1, 1]
        row_z = ty * b[1, 2]
        first = row * width
        end = min(width, count - first)
        if kind == FIELD_ZERO:
            for c in range(end):
                d[0, c] = ex + (columns[0, c] + row_x) + 0.0 - ex
                d[1, c] = ey + (columns[1, c] + row_y) + 0.0 - ey
                d[2, c] = ez + (columns[2, c] + row_z) + 0.0 - ez
        else:
            for c in range(end):  # fill_field's arithmetic, then its scale and its finite check
                m = first + c
                # k is 1 for the colour field: times 1 is exact, and a load apart keeps this loop branch-free
                k = abs(depth[m] - z0) if kind == FIELD_DEPTH else 1.0
                d[0, c] = k * (2.0 * color[m, 0] - 1.0)
                d[1, c] = k * (2.0 * color[m, 1] - 1.0)
                d[2, c] = k * (2.0 * color[m, 2] - 1.0)
            for c in range(end):
                a = d[0, c]
                bb = d[1, c]
                cc = d[2, c]
                px = scale * (a * rx + bb * ux + cc * fx)
                py = scale * (a * ry + bb * uy + cc * fy)
                pz = scale * (a * rz + bb * uz + cc * fz)
                d[0, c] = ex + (columns[0, c] + row_x) + (px if math.isfinite(px) else 0.0) - ex
                d[1, c] = ey + (columns[1, c] + row_y) + (py if math.isfinite(py) else 0.0) - ey
                d[2, c] = ez + (columns[2, c] + row_z) + (pz if math.isfinite(pz) else 0.0) - ez
        for c in range(end):
            norm2 = d[0, c] * d[0, c] + d[1, c] * d[1, c] + d[2, c] * d[2, c]
            ok = (norm2 > 0.0) & (norm2 < math.inf)  # else the eye is on its target, or an input is not finite
            bad += 0 if ok else 1
            d[3, c] = 1.0 / math.sqrt(norm2) if ok else math.nan  # a NaN ray, which misses
        for c in range(end):
            m = first + c
            directions[m, 0] = d[0, c] * d[3, c]
            directions[m, 1] = d[1, c] * d[3, c]
            directions[m, 2] = d[2, c] * d[3, c]
    return bad
