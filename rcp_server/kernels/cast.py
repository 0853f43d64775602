"""Camera assignment, fused and compiled: the previous iteration's data -> per-sample rays.

``cast_rays`` builds every sample's ray with the built-in mappings' displacement fields fused in
(``fill_field``, which the image-space method also runs alone). ``tests/engine/test_kernels.py`` holds
their numpy reference.
"""

from __future__ import annotations

import math

from .jit import jit

# how cast_rays gets a pixel's displacement field D: the built-in mappings fused, or a field given
FIELD_ZERO, FIELD_COLOR, FIELD_DEPTH, FIELD_NORMAL, FIELD_GIVEN = 0, 1, 2, 3, 4


@jit
def fill_field(field, basis, previous, z0, noise, noise_scale, pixels, out):
    """``field.scale * (D + noise_scale * noise)`` for the listed pixels into out (n, 3) float64; see
    mappings.py for D. The rows of pixels not listed are left as they are.

    field : a bundles.Field;  basis : (3, 3) rows r, u, f;  previous : bundles.Channels, I_{n-1} per pixel
    (dummies where the mapping does not read them);  z0 : focus depth;  noise : (n, 3) float32;
    pixels : (m,) int64 indices of the pixels to fill.
    One loop per kind (a branch per pixel costs more than the field itself). Non-finite values move nothing.
    """
    if field.kind == FIELD_ZERO:
        for pix in pixels:
            out[pix, 0] = out[pix, 1] = out[pix, 2] = 0.0
        return
    if field.kind == FIELD_COLOR or field.kind == FIELD_DEPTH:
        for pix in pixels:
            k = abs(previous.depth[pix] - z0) if field.kind == FIELD_DEPTH else 1.0
            a = 2.0 * previous.color[pix, 0] - 1.0
            b = 2.0 * previous.color[pix, 1] - 1.0
            c = 2.0 * previous.color[pix, 2] - 1.0
            for q in range(3):
                out[pix, q] = k * (a * basis[0, q] + b * basis[1, q] + c * basis[2, q])
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

    eye : (3,) float64;  plane : a bundles.ImagePlane (the frame camera's plane and the region, pixels row-major)
    xi, eta : (n, spp) float64 sub-pixel offsets of each sample (not read at 1 spp: the centre)
    previous : bundles.Channels, I_{n-1} per pixel (dummies where the mapping does not read them)
    target, eye_field : bundles.Field of V_p (scale lambda_p * p) and of V_e (scale lambda_e)
    noise : (n, 3) world-space random vectors, added to both fields times noise_scale
    pixels : (m,) int64 the pixels to cast, ascending: sample k of the m-th listed pixel is ray m * spp + k
    (a painting that reuses unchanged pixels casts only the others)
    v_p, v_e : (n, 3) float64 out: the displacements (scratch owned by the caller: a large allocation
    inside a kernel costs more than the whole pass); a field of kind FIELD_ZERO is not written
    origins, directions : (n*spp, 3) float32 out (the first m*spp rows): P_e' = eye + V_e, unit direction to
    P_p' = P_p(s, t) + V_p with P_p as in camera.py. A non-finite displacement moves nothing.
    write_origins : False when the eyes do not move and origins already hold the eye (saves a pass of writes)
    """
    basis, tan_half, aspect = plane.basis, plane.tan_half, plane.aspect
    full_width, full_height = plane.full_width, plane.full_height
    x0, y0, width = plane.x0, plane.y0, plane.width
    spp = xi.shape[1]
    # what does not move is neither filled nor read: at this size every pass over memory counts
    targets_move = target.kind != FIELD_ZERO
    eyes_move = eye_field.kind != FIELD_ZERO
    if targets_move:
        fill_field(target, basis, previous, z0, noise, noise_scale, pixels, v_p)
    if eyes_move:
        fill_field(eye_field, basis, previous, z0, noise, noise_scale, pixels, v_e)
    px = py = pz = 0.0
    ox = eye[0]
    oy = eye[1]
    oz = eye[2]
    sx0 = 0.5
    # plane point = centre + sx * r + ty * u with centre = eye + f; sx, ty affine in the sample position
    cx = eye[0] + basis[2, 0]
    cy = eye[1] + basis[2, 1]
    cz = eye[2] + basis[2, 2]
    sx_scale = 2.0 * aspect * tan_half / full_width
    ty_scale = 2.0 * tan_half / full_height
    bad = 0
    row = 0
    row_end = -1  # the first pixel past the current row
    ty0 = 0.0
    for m in range(len(pixels)):
        pix = pixels[m]
        if pix >= row_end:  # pixels ascend: a division once a row, not once a pixel (it costs as much as a ray)
            row = pix // width
            row_end = (row + 1) * width
            ty0 = tan_half - (y0 + row) * ty_scale
        i = x0 + pix - row * width
        if targets_move:
            px = v_p[pix, 0]
            py = v_p[pix, 1]
            pz = v_p[pix, 2]
        if eyes_move:
            ox = eye[0] + v_e[pix, 0]
            oy = eye[1] + v_e[pix, 1]
            oz = eye[2] + v_e[pix, 2]
        for k in range(spp):
            # one sample sits at the pixel centre (MISSION.md); only jittered samples read their offsets
            sx = (i + (xi[pix, k] if spp > 1 else sx0)) * sx_scale - aspect * tan_half
            ty = ty0 - (eta[pix, k] if spp > 1 else sx0) * ty_scale
            dx = cx + sx * basis[0, 0] + ty * basis[1, 0] + px - ox
            dy = cy + sx * basis[0, 1] + ty * basis[1, 1] + py - oy
            dz = cz + sx * basis[0, 2] + ty * basis[1, 2] + pz - oz
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
