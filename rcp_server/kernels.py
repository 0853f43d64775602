"""The two hot passes of an iteration, fused and compiled (numba); numpy cannot fuse them.

``cast_rays`` turns the previous iteration's data into per-sample rays (camera assignment, with the
built-in mappings fused in) and ``shade``
turns Embree's hits into per-pixel data (shading plus the per-pixel mean). Both release the GIL so
tiles run on threads side by side with Embree. ``tests/test_kernels.py`` holds a plain numpy
reference of each and checks that they agree.
"""

from __future__ import annotations

import math

import numba
import numpy as np

# fast math without the no-NaN/no-inf assumptions: the kernels test for NaN rays on purpose
_jit = numba.njit(nogil=True, cache=True, error_model="numpy")


# how cast_rays gets a pixel's displacement field D: the built-in mappings fused, or a field given
FIELD_ZERO, FIELD_COLOR, FIELD_DEPTH, FIELD_NORMAL, FIELD_GIVEN = 0, 1, 2, 3, 4


@_jit
def fill_field(kind, scale, basis, color, depth, normal, direction, z0, given, noise, noise_scale, out):
    """``scale * (D + noise_scale * noise)`` for every pixel into out (n, 3) float64; see mappings.py for D.

    One loop per kind (a branch per pixel costs more than the field itself). Non-finite values move nothing.
    """
    n = out.shape[0]
    if kind == FIELD_ZERO:
        out[:] = 0.0
        return
    if kind == FIELD_COLOR or kind == FIELD_DEPTH:
        for pix in range(n):
            k = abs(depth[pix] - z0) if kind == FIELD_DEPTH else 1.0
            a = 2.0 * color[pix, 0] - 1.0
            b = 2.0 * color[pix, 1] - 1.0
            c = 2.0 * color[pix, 2] - 1.0
            for q in range(3):
                out[pix, q] = k * (a * basis[0, q] + b * basis[1, q] + c * basis[2, q])
    elif kind == FIELD_NORMAL:
        for pix in range(n):
            out[pix, 0] = direction[pix, 1] * normal[pix, 2] - direction[pix, 2] * normal[pix, 1]
            out[pix, 1] = direction[pix, 2] * normal[pix, 0] - direction[pix, 0] * normal[pix, 2]
            out[pix, 2] = direction[pix, 0] * normal[pix, 1] - direction[pix, 1] * normal[pix, 0]
    else:
        for pix in range(n):
            for q in range(3):
                out[pix, q] = given[pix, q]
    for pix in range(n):
        for q in range(3):
            v = scale * (out[pix, q] + noise_scale * noise[pix, q]) if noise_scale != 0.0 else scale * out[pix, q]
            out[pix, q] = v if math.isfinite(v) else 0.0


@_jit
def cast_rays(
    eye,
    basis,
    tan_half,
    aspect,
    full_width,
    full_height,
    x0,
    y0,
    width,
    xi,
    eta,
    color,
    depth,
    normal,
    direction,
    z0,
    target_kind,
    target_scale,
    target_given,
    eye_kind,
    eye_scale,
    eye_given,
    noise,
    noise_scale,
    v_p,
    v_e,
    origins,
    directions,
    write_origins,
):
    """Per-pixel cameras for every sample: camera assignment fused with the mapping. Returns the number
    of rays that came out non-finite (a NaN or infinite input), so the caller masks only when needed.

    eye : (3,) float64;  basis : (3, 3) rows r, u, f;  tan_half : tan(fov/2);  aspect : W / H
    full_width, full_height : W, H;  x0, y0, width : the region's corner and width (pixels row-major)
    xi, eta : (n, spp) float64 sub-pixel offsets of each sample (not read at 1 spp: the centre)
    color, depth, normal, direction : I_{n-1} per pixel (dummies where the mapping does not read them)
    *_kind : FIELD_*; *_scale : lambda_p * p and lambda_e; *_given : (n, 3) precomputed fields (FIELD_GIVEN)
    noise : (n, 3) world-space random vectors, added to both fields times noise_scale
    v_p, v_e : (n, 3) float64 out: the displacements (scratch owned by the caller: a large allocation
    inside a kernel costs more than the whole pass); a field of kind FIELD_ZERO is not written
    xi, eta at 1 spp are not read: that sample is the pixel centre
    origins, directions : (n*spp, 3) float32 out: P_e' = eye + V_e, unit direction to
    P_p' = P_p(s, t) + V_p with P_p as in camera.py. A non-finite displacement moves nothing.
    write_origins : False when the eyes do not move and origins already hold the eye (saves a pass of writes)
    """
    n_pix, spp = xi.shape
    # what does not move is neither filled nor read: at this size every pass over memory counts
    targets_move = target_kind != FIELD_ZERO
    eyes_move = eye_kind != FIELD_ZERO
    if targets_move:
        fill_field(
            target_kind, target_scale, basis, color, depth, normal, direction, z0, target_given, noise, noise_scale, v_p
        )
    if eyes_move:
        fill_field(eye_kind, eye_scale, basis, color, depth, normal, direction, z0, eye_given, noise, noise_scale, v_e)
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
    for row in range(n_pix // width):  # nested loops: an integer division per pixel costs more than a ray
        ty0 = tan_half - (y0 + row) * ty_scale
        for col in range(width):
            pix = row * width + col
            i = x0 + col
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
                s = pix * spp + k
                if write_origins:
                    origins[s, 0] = ox
                    origins[s, 1] = oy
                    origins[s, 2] = oz
                directions[s, 0] = dx * inv
                directions[s, 1] = dy * inv
                directions[s, 2] = dz * inv
    return bad


@numba.njit(inline="always")
def _inverse_length(length2):
    """``1 / sqrt(length2)``, 0 for 0. Interpolated unit normals are nearly unit: there three Newton steps
    from the tangent at 1 are exact to 1e-8 relative, and cheaper than a square root and a division."""
    if 0.6 <= length2 <= 1.4:
        y = 1.5 - 0.5 * length2
        y *= 1.5 - 0.5 * length2 * y * y
        y *= 1.5 - 0.5 * length2 * y * y
        return y * (1.5 - 0.5 * length2 * y * y)
    return 1.0 / math.sqrt(length2) if length2 > 0.0 else 0.0


@numba.njit(inline="always")
def fast_atan2(y, x):
    """atan2 within 1e-5 rad (a 1024-texel panorama's texel is 6e-3 rad) at a fraction of libm's cost."""
    ax = abs(x)
    ay = abs(y)
    big = max(ax, ay)
    if big == 0.0:
        return 0.0
    z = min(ax, ay) / big
    z2 = z * z
    a = z * (
        0.99997726 + z2 * (-0.33262347 + z2 * (0.19354346 + z2 * (-0.11643287 + z2 * (0.05265332 + z2 * -0.01172120))))
    )
    if ay > ax:
        a = 0.5 * math.pi - a
    if x < 0.0:
        a = math.pi - a
    return -a if y < 0.0 else a


@numba.njit(inline="always")  # two call sites in shade; an out-of-line call passes the array by value
def _bilinear(texels, offset, width, height, x, y, wrap_y):
    """Bilinear lookup at continuous texel coordinates (x, y), as an (r, g, b) tuple: x wraps; y wraps for
    a tiling texture and clamps for a panorama (whose top and bottom rows are the poles)."""
    x -= 0.5
    y -= 0.5
    fx0 = math.floor(x)
    fy0 = math.floor(y)
    fx = x - fx0
    fy = y - fy0
    c0 = int(fx0) % width
    c1 = c0 + 1 if c0 + 1 < width else 0
    if wrap_y:
        r0 = int(fy0) % height
        r1 = r0 + 1 if r0 + 1 < height else 0
    else:
        r0 = min(max(int(fy0), 0), height - 1)
        r1 = min(max(int(fy0) + 1, 0), height - 1)
    a = offset + r0 * width
    b = offset + r1 * width
    w00 = (1.0 - fx) * (1.0 - fy)
    w01 = fx * (1.0 - fy)
    w10 = (1.0 - fx) * fy
    w11 = fx * fy
    return (
        w00 * texels[a + c0, 0] + w01 * texels[a + c1, 0] + w10 * texels[b + c0, 0] + w11 * texels[b + c1, 0],
        w00 * texels[a + c0, 1] + w01 * texels[a + c1, 1] + w10 * texels[b + c0, 1] + w11 * texels[b + c1, 1],
        w00 * texels[a + c0, 2] + w01 * texels[a + c1, 2] + w10 * texels[b + c0, 2] + w11 * texels[b + c1, 2],
    )


@_jit
def shade(
    origins,
    directions,
    face,
    t,
    b1,
    b2,
    spp,
    normals,
    colors,
    uv,
    texture_id,
    texels,
    texture_offset,
    texture_width,
    texture_height,
    environment,
    light_dir,
    ambient,
    lit,
    eye,
    forward,
    z_max,
    out_color,
    out_depth,
    out_normal,
    out_direction,
    need_depth,
    need_normal,
    need_direction,
):
    """Shade every sample and average the samples of each pixel.

    origins, directions : (n*spp, 3) float32 rays; face, t, b1, b2 : their hits (face -1 on a miss)
    normals, colors : (F, 3, 3) float32; uv : (F, 3, 2); texture_id : (F,) int32; texels etc: packed textures
    environment : (h, w, 3) float32 equirectangular; light_dir : (3,) float64 travel direction
    out_color : (n, 3) float32 displayed color in [0, 1]; out_depth : (n,) float32 view depth along
    ``forward`` from ``eye`` (``z_max`` on a miss); out_normal : (n, 3) world normal (0 on a miss);
    out_direction : (n, 3) ray direction. The out_* that are not needed are not written.
    """
    n_pix = out_color.shape[0]
    env_h = environment.shape[0]
    env_w = environment.shape[1]
    env_flat = environment.reshape(env_h * env_w, 3)
    inv_spp = 1.0 / spp
    panorama = env_w * env_h > 1
    block = 256  # pixels
    sky = np.empty((block * spp, 2))  # panorama texel coordinates of one block's misses
    for first in range(0, n_pix, block):
        last = min(first + block, n_pix)
        base = first * spp
        # ---- where this block's misses look in the panorama: the trigonometry runs in a short loop of its
        # own, whose iterations the CPU overlaps; inside the shading loop it cost three times as much ----
        if panorama:
            for s in range(base, last * spp):
                if face[s] < 0:
                    dx = directions[s, 0]
                    dy = directions[s, 1]
                    dz = directions[s, 2]
                    lon = fast_atan2(dx, -dz)
                    lat = 0.5 * math.pi - fast_atan2(dy, math.sqrt(dx * dx + dz * dz))
                    sky[s - base, 0] = (lon / (2.0 * math.pi) + 0.5) * env_w
                    sky[s - base, 1] = lat / math.pi * env_h
        # scalars rather than small arrays throughout: they stay in registers
        for pix in range(first, last):
            acc_r = acc_g = acc_b = 0.0
            acc_nx = acc_ny = acc_nz = 0.0
            acc_dx = acc_dy = acc_dz = 0.0
            acc_z = 0.0
            for s in range(pix * spp, (pix + 1) * spp):
                f = face[s]
                dx = directions[s, 0]
                dy = directions[s, 1]
                dz = directions[s, 2]
                finite = dx == dx and dy == dy and dz == dz  # a NaN ray misses and sees black
                if f >= 0:
                    # ---- surface: albedo from corner colors (times texture), then light ----
                    w1 = b1[s]
                    w2 = b2[s]
                    w0 = 1.0 - w1 - w2
                    r = w0 * colors[f, 0, 0] + w1 * colors[f, 1, 0] + w2 * colors[f, 2, 0]
                    g = w0 * colors[f, 0, 1] + w1 * colors[f, 1, 1] + w2 * colors[f, 2, 1]
                    b = w0 * colors[f, 0, 2] + w1 * colors[f, 1, 2] + w2 * colors[f, 2, 2]
                    tid = texture_id[f]
                    if tid >= 0:
                        u = w0 * uv[f, 0, 0] + w1 * uv[f, 1, 0] + w2 * uv[f, 2, 0]
                        v = w0 * uv[f, 0, 1] + w1 * uv[f, 1, 1] + w2 * uv[f, 2, 1]
                        tw = texture_width[tid]
                        th = texture_height[tid]
                        tr, tg, tb = _bilinear(texels, texture_offset[tid], tw, th, u * tw, (1.0 - v) * th, True)
                        r *= tr
                        g *= tg
                        b *= tb
                    nx = w0 * normals[f, 0, 0] + w1 * normals[f, 1, 0] + w2 * normals[f, 2, 0]
                    ny = w0 * normals[f, 0, 1] + w1 * normals[f, 1, 1] + w2 * normals[f, 2, 1]
                    nz = w0 * normals[f, 0, 2] + w1 * normals[f, 1, 2] + w2 * normals[f, 2, 2]
                    inv = _inverse_length(nx * nx + ny * ny + nz * nz)
                    if inv > 0.0:
                        nx *= inv
                        ny *= inv
                        nz *= inv
                    if lit:
                        # two-sided: light the side the ray sees
                        facing = -1.0 if nx * dx + ny * dy + nz * dz > 0.0 else 1.0
                        lambert = -facing * (nx * light_dir[0] + ny * light_dir[1] + nz * light_dir[2])
                        k = ambient + (1.0 - ambient) * max(lambert, 0.0)
                        r *= k
                        g *= k
                        b *= k
                    if need_depth:
                        ts = t[s]
                        acc_z += (
                            (origins[s, 0] + ts * dx - eye[0]) * forward[0]
                            + (origins[s, 1] + ts * dy - eye[1]) * forward[1]
                            + (origins[s, 2] + ts * dz - eye[2]) * forward[2]
                        )
                    if need_normal:
                        acc_nx += nx
                        acc_ny += ny
                        acc_nz += nz
                else:
                    # ---- miss: the environment, equirectangular ----
                    if not finite:
                        r = g = b = 0.0
                    elif env_w * env_h == 1:
                        r = env_flat[0, 0]
                        g = env_flat[0, 1]
                        b = env_flat[0, 2]
                    else:
                        r, g, b = _bilinear(env_flat, 0, env_w, env_h, sky[s - base, 0], sky[s - base, 1], False)
                    if need_depth:
                        acc_z += z_max
                acc_r += min(max(r, 0.0), 1.0)
                acc_g += min(max(g, 0.0), 1.0)
                acc_b += min(max(b, 0.0), 1.0)
                if need_direction and finite:
                    acc_dx += dx
                    acc_dy += dy
                    acc_dz += dz
            out_color[pix, 0] = acc_r * inv_spp
            out_color[pix, 1] = acc_g * inv_spp
            out_color[pix, 2] = acc_b * inv_spp
            if need_depth:
                out_depth[pix] = acc_z * inv_spp
            if need_normal:
                out_normal[pix, 0] = acc_nx * inv_spp
                out_normal[pix, 1] = acc_ny * inv_spp
                out_normal[pix, 2] = acc_nz * inv_spp
            if need_direction:
                dlen = math.sqrt(acc_dx * acc_dx + acc_dy * acc_dy + acc_dz * acc_dz)
                inv = 1.0 / dlen if dlen > 0.0 else 0.0
                out_direction[pix, 0] = acc_dx * inv
                out_direction[pix, 1] = acc_dy * inv
                out_direction[pix, 2] = acc_dz * inv
