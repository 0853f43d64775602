"""Camera assignment, fused and compiled: the previous iteration's data -> per-sample rays.

``cast_rays`` builds every sample's ray with the built-in mappings' displacement fields fused in
(``fill_field``, which the image-space method also runs alone). ``tests/engine/test_kernels.py`` holds
their numpy reference.
"""

from __future__ import annotations

import math

from .jit import jit
from .projection import EQUIRECT, centre_frame, locate, target_offset, tile_pixel

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


@jit
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
):
    """Per-pixel cameras for every sample: camera assignment fused with the mapping. Returns the number
    of rays that came out non-finite (a NaN or infinite input), so the caller masks only when needed.

    eye : (3,) float64 the camera's;  plane : a bundles.ImagePlane (the projection and the tile, pixels row-major)
    xi, eta : (n, spp) float64 sub-pixel offsets of each sample (not read at 1 spp: the centre)
    previous : bundles.Channels, I_{n-1} per pixel (dummies where the mapping does not read them)
    target, eye_field : bundles.Field of V_p (scale lambda_p * p) and of V_e (scale lambda_e)
    noise : (n, 3) world-space random vectors, added to both fields times noise_scale
    pixels : (m,) int64 the pixels to cast, ascending: sample k of the m-th listed pixel is ray m * spp + k
    v_p, v_e : (n, 3) float64 out: the displacements (scratch owned by the caller: a large allocation
    inside a kernel costs more than the whole pass); a field of kind FIELD_ZERO is not written
    origins, directions : (n*spp, 3) float32 out (the first m*spp rows): P_e' = eye_ij + V_e, unit direction to
    P_p' = P_p(s, t) + V_p with eye_ij and P_p as in camera.py. A non-finite displacement moves nothing.
    write_origins : False when the eyes do not move and origins already hold the eye (saves a pass of writes)
    """
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
