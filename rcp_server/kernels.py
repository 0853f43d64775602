"""The two hot passes of an iteration, fused and compiled (numba); numpy cannot fuse them.

``cast_rays`` turns per-pixel displacements into per-sample rays (camera assignment) and ``shade``
turns Embree's hits into per-pixel data (shading plus the per-pixel mean). Both release the GIL so
tiles run on threads side by side with Embree. ``tests/test_kernels.py`` holds a plain numpy
reference of each and checks that they agree.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(nogil=True, cache=True, error_model="numpy")


@_jit
def cast_rays(plane, eye, v_p, v_e, spp, origins, directions):
    """Per-pixel cameras for every sample.

    plane : (n*spp, 3) float64 image-plane points P_p; eye : (3,) float64
    v_p, v_e : (n, 3) float32 target and eye displacement of each pixel
    origins, directions : (n*spp, 3) float32 outputs: P_e' = eye + V_e, unit direction to P_p' = P_p + V_p
    """
    for s in range(plane.shape[0]):
        pix = s // spp
        norm2 = 0.0
        d = np.empty(3)
        for k in range(3):
            o = eye[k] + v_e[pix, k]
            d[k] = plane[s, k] + v_p[pix, k] - o
            origins[s, k] = o
            norm2 += d[k] * d[k]
        inv = 1.0 / math.sqrt(norm2) if norm2 > 0.0 else math.nan  # eye on target: no ray (it misses)
        for k in range(3):
            directions[s, k] = d[k] * inv


@_jit
def _bilinear(texels, offset, width, height, x, y, out):
    """Bilinear lookup at continuous texel coordinates (x, y), wrapping in x and clamping in y."""
    x -= 0.5
    y -= 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    for c in range(3):
        out[c] = 0.0
    for dy in range(2):
        row = min(max(int(y0) + dy, 0), height - 1)
        wy = fy if dy else 1.0 - fy
        for dx in range(2):
            col = (int(x0) + dx) % width
            w = wy * (fx if dx else 1.0 - fx)
            for c in range(3):
                out[c] += w * texels[offset + row * width + col, c]


@_jit
def shade(origins, directions, face, t, b1, b2, spp,
          normals, colors, uv, texture_id, texels, texture_offset, texture_width, texture_height,
          environment, light_dir, ambient, lit, eye, forward, z_max,
          out_color, out_depth, out_normal, out_direction, need_depth, need_normal, need_direction):
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
    rgb = np.empty(3)
    tex = np.empty(3)
    nrm = np.empty(3)
    acc_c = np.empty(3)
    acc_n = np.empty(3)
    acc_d = np.empty(3)
    for pix in range(n_pix):
        acc_c[:] = 0.0
        acc_n[:] = 0.0
        acc_d[:] = 0.0
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
                for c in range(3):
                    rgb[c] = w0 * colors[f, 0, c] + w1 * colors[f, 1, c] + w2 * colors[f, 2, c]
                    nrm[c] = w0 * normals[f, 0, c] + w1 * normals[f, 1, c] + w2 * normals[f, 2, c]
                tid = texture_id[f]
                if tid >= 0:
                    u = w0 * uv[f, 0, 0] + w1 * uv[f, 1, 0] + w2 * uv[f, 2, 0]
                    v = w0 * uv[f, 0, 1] + w1 * uv[f, 1, 1] + w2 * uv[f, 2, 1]
                    tw = texture_width[tid]
                    th = texture_height[tid]
                    _bilinear(texels, texture_offset[tid], tw, th, u * tw, (1.0 - v) * th, tex)
                    for c in range(3):
                        rgb[c] *= tex[c]
                nlen = math.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
                if nlen > 0.0:
                    for c in range(3):
                        nrm[c] /= nlen
                if lit:
                    # two-sided: light the side the ray sees
                    facing = -1.0 if nrm[0] * dx + nrm[1] * dy + nrm[2] * dz > 0.0 else 1.0
                    lambert = -facing * (nrm[0] * light_dir[0] + nrm[1] * light_dir[1] + nrm[2] * light_dir[2])
                    shade_k = ambient + (1.0 - ambient) * max(lambert, 0.0)
                    for c in range(3):
                        rgb[c] *= shade_k
                if need_depth:
                    ts = t[s]
                    acc_z += ((origins[s, 0] + ts * dx - eye[0]) * forward[0]
                              + (origins[s, 1] + ts * dy - eye[1]) * forward[1]
                              + (origins[s, 2] + ts * dz - eye[2]) * forward[2])
                if need_normal:
                    for c in range(3):
                        acc_n[c] += nrm[c]
            else:
                # ---- miss: the environment, equirectangular ----
                if finite:
                    lon = math.atan2(dx, -dz)
                    lat = math.acos(min(max(dy, -1.0), 1.0))
                    _bilinear(env_flat, 0, env_w, env_h, (lon / (2.0 * math.pi) + 0.5) * env_w,
                              lat / math.pi * env_h, rgb)
                else:
                    for c in range(3):
                        rgb[c] = 0.0
                if need_depth:
                    acc_z += z_max
            for c in range(3):
                acc_c[c] += min(max(rgb[c], 0.0), 1.0)
            if need_direction and finite:
                acc_d[0] += dx
                acc_d[1] += dy
                acc_d[2] += dz
        for c in range(3):
            out_color[pix, c] = acc_c[c] * inv_spp
        if need_depth:
            out_depth[pix] = acc_z * inv_spp
        if need_normal:
            for c in range(3):
                out_normal[pix, c] = acc_n[c] * inv_spp
        if need_direction:
            dlen = math.sqrt(acc_d[0] ** 2 + acc_d[1] ** 2 + acc_d[2] ** 2)
            for c in range(3):
                out_direction[pix, c] = acc_d[c] / dlen if dlen > 0.0 else 0.0
