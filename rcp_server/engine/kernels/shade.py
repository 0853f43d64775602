"""Shading, fused and compiled: Embree's hits -> per-pixel data (shading plus the per-pixel mean).

``tests/engine/test_shade.py`` holds its numpy reference.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .jit import jit
from .prefetch import prefetch
from .projection import (
    EQUIRECT,
    SIDE_BY_SIDE,
    TOP_BOTTOM,
    centre_frame,
    fast_atan2,
    locate,
    tile_pixel,
    to_pixel,
)


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
def _wrap(k, n):
    """``k % n`` (n > 0), the division only off the texture's edge: a 64-bit division per texel fetch cost
    more than the fetch, and a texture coordinate mostly lies on the texture already."""
    return k if 0 <= k < n else k % n


@numba.njit(inline="always")
def _bilinear_site(offset, width, height, x, y, wrap_y):
    """Where a bilinear lookup at continuous texel coordinates (x, y) reads, in an image whose first texel is
    ``offset``: its four nearest texels (top left, top right, bottom left, bottom right) and the weights of the
    right and bottom ones. x wraps; y wraps for a tiling texture and clamps for a panorama (whose top and bottom
    rows are the poles)."""
    x -= 0.5
    y -= 0.5
    fx0 = math.floor(x)
    fy0 = math.floor(y)
    c0 = _wrap(int(fx0), width)
    c1 = c0 + 1 if c0 + 1 < width else 0
    if wrap_y:
        r0 = _wrap(int(fy0), height)
        r1 = r0 + 1 if r0 + 1 < height else 0
    else:
        r0 = min(max(int(fy0), 0), height - 1)
        r1 = min(max(int(fy0) + 1, 0), height - 1)
    a = offset + r0 * width
    b = offset + r1 * width
    return a + c0, a + c1, b + c0, b + c1, x - fx0, y - fy0


@numba.njit(inline="always")
def _bilinear_mix(texels, k00, k01, k10, k11, fx, fy):
    """The bilinear blend of texels k00, k01, k10, k11 (:func:`_bilinear_site`) of (T, 3) float ``texels``, as
    an (r, g, b) tuple."""
    w00 = (1.0 - fx) * (1.0 - fy)
    w01 = fx * (1.0 - fy)
    w10 = (1.0 - fx) * fy
    w11 = fx * fy
    return (
        w00 * texels[k00, 0] + w01 * texels[k01, 0] + w10 * texels[k10, 0] + w11 * texels[k11, 0],
        w00 * texels[k00, 1] + w01 * texels[k01, 1] + w10 * texels[k10, 1] + w11 * texels[k11, 1],
        w00 * texels[k00, 2] + w01 * texels[k01, 2] + w10 * texels[k10, 2] + w11 * texels[k11, 2],
    )


def _srgb_tables() -> tuple[np.ndarray, np.ndarray]:
    """8-bit display value -> linear (256,) float64, and linear in 4096 steps -> display (4097,) float64."""
    x = np.arange(256) / 255.0
    decode = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    y = np.arange(4097) / 4096.0
    encode = np.where(y <= 0.0031308, 12.92 * y, 1.055 * y ** (1 / 2.4) - 0.055)
    return decode, encode


_DECODE, _ENCODE = _srgb_tables()


@numba.njit(inline="always")
def _encode(linear):
    """Linear [0, 1] -> display, from the table, interpolated (exact to 1e-4 where the curve is steep)."""
    x = min(max(linear, 0.0), 1.0) * 4096.0
    k = min(int(x), 4095)
    w = x - k
    return _ENCODE[k] + w * (_ENCODE[k + 1] - _ENCODE[k])


@numba.njit(inline="always")
def _texel_site(offset, width, height, u, v):
    """Where a texture's bilinear lookup at (u, v) (both wrap) reads (:func:`_bilinear_site`)."""
    return _bilinear_site(offset, width, height, u * width, (1.0 - v) * height, True)


@numba.njit(inline="always")
def _texel_mix(texels, k00, k01, k10, k11, fx, fy):
    """The display color of the bilinear blend of texels k00, k01, k10, k11 (``_texel_site``), an (r, g, b)
    tuple in [0, 1], filtered in linear light (a blend of display values darkens an edge between light and dark
    texels) and encoded back."""
    w00 = (1.0 - fx) * (1.0 - fy)
    w01 = fx * (1.0 - fy)
    w10 = (1.0 - fx) * fy
    w11 = fx * fy
    out_r = (
        w00 * _DECODE[texels[k00, 0]]
        + w01 * _DECODE[texels[k01, 0]]
        + w10 * _DECODE[texels[k10, 0]]
        + w11 * _DECODE[texels[k11, 0]]
    )
    out_g = (
        w00 * _DECODE[texels[k00, 1]]
        + w01 * _DECODE[texels[k01, 1]]
        + w10 * _DECODE[texels[k10, 1]]
        + w11 * _DECODE[texels[k11, 1]]
    )
    out_b = (
        w00 * _DECODE[texels[k00, 2]]
        + w01 * _DECODE[texels[k01, 2]]
        + w10 * _DECODE[texels[k10, 2]]
        + w11 * _DECODE[texels[k11, 2]]
    )
    return _encode(out_r), _encode(out_g), _encode(out_b)


@numba.njit(inline="always")
def texel_color(texels, offset, width, height, u, v):
    """A texture's display color at (u, v) (both wrap), an (r, g, b) tuple in [0, 1]: bilinear between its
    four nearest 8-bit texels in linear light (:func:`_texel_site`, :func:`_texel_mix`).
    texels : (T, 3) uint8 RGB, every texture packed."""
    k00, k01, k10, k11, fx, fy = _texel_site(offset, width, height, u, v)
    return _texel_mix(texels, k00, k01, k10, k11, fx, fy)


@numba.njit(inline="always")
def _ink_at(ink, plane, side, ex, ey, ez, x, y, z):
    """The ink at the pixel of the painting where world point (x, y, z) is seen from the eye ``e`` on ``side``, if
    it lies on the surface that pixel saw (its distance within 2%); 0 elsewhere and off that eye's image."""
    vx = x - ex
    vy = y - ey
    vz = z - ez
    px, py, ok = to_pixel(plane, side, vx, vy, vz)
    if not ok:
        return 0.0
    col = int(math.floor(px + 0.5))
    row = int(math.floor(py + 0.5))
    x_off = plane.eye_width if side > 0 and plane.layout == SIDE_BY_SIDE else 0
    y_off = plane.eye_height if side > 0 and plane.layout == TOP_BOTTOM else 0
    if not (x_off <= col < x_off + plane.eye_width and y_off <= row < y_off + plane.eye_height):
        return 0.0
    k = row * plane.full_width + col
    distance = math.sqrt(vx * vx + vy * vy + vz * vz)
    return float(ink.ink[k]) if abs(ink.distance[k] - distance) <= 0.02 * distance else 0.0


@numba.njit(inline="always")
def _interpolated(normals, f, w0, w1, w2):
    """Face ``f``'s shading normal at barycentric weights (w0, w1, w2), as its corners' blend (not unit)."""
    return (
        w0 * normals[f, 0, 0] + w1 * normals[f, 1, 0] + w2 * normals[f, 2, 0],
        w0 * normals[f, 0, 1] + w1 * normals[f, 1, 1] + w2 * normals[f, 2, 1],
        w0 * normals[f, 0, 2] + w1 * normals[f, 1, 2] + w2 * normals[f, 2, 2],
    )


@numba.njit(inline="always")
def _unit(nx, ny, nz):
    """(nx, ny, nz) made unit length; as it is where its length is 0."""
    inv = _inverse_length(nx * nx + ny * ny + nz * nz)
    if inv > 0.0:
        return nx * inv, ny * inv, nz * inv
    return nx, ny, nz


@numba.njit(inline="always")
def _lambert(nx, ny, nz, dx, dy, dz, lx, ly, lz):
    """The light on unit normal n seen along ray direction d from light travelling along l: two-sided, on the
    side the ray sees."""
    facing = nx * dx + ny * dy + nz * dz > 0.0
    return max((nx * lx + ny * ly + nz * lz) * (1.0 if facing else -1.0), 0.0)


@numba.njit(inline="always")
def _corners(colors, uv, f, w0, w1, w2):
    """Face ``f``'s corner colors and texture coordinates at barycentric weights (w0, w1, w2): (r, g, b, u, v)."""
    r = w0 * colors[f, 0, 0] + w1 * colors[f, 1, 0] + w2 * colors[f, 2, 0]
    g = w0 * colors[f, 0, 1] + w1 * colors[f, 1, 1] + w2 * colors[f, 2, 1]
    b = w0 * colors[f, 0, 2] + w1 * colors[f, 1, 2] + w2 * colors[f, 2, 2]
    u = w0 * uv[f, 0, 0] + w1 * uv[f, 1, 0] + w2 * uv[f, 2, 0]
    v = w0 * uv[f, 0, 1] + w1 * uv[f, 1, 1] + w2 * uv[f, 2, 1]
    return r, g, b, u, v


@numba.njit(inline="always")
def _albedo(colors, uv, texture_id, texels, texture_offset, texture_width, texture_height, f, w0, w1, w2):
    """The unlit colour of face ``f`` at barycentric weights (w0, w1, w2), its corner colors times its texture,
    and the texture coordinates there: (r, g, b, u, v), for :func:`record_surfaces`. ``shade`` runs the same two
    steps (:func:`_corners`, then :func:`texel_color`) in passes of its own."""
    r, g, b, u, v = _corners(colors, uv, f, w0, w1, w2)
    tid = texture_id[f]
    if tid >= 0:
        tr, tg, tb = texel_color(texels, texture_offset[tid], texture_width[tid], texture_height[tid], u, v)
        r *= tr
        g *= tg
        b *= tb
    return r, g, b, u, v


@jit
def shade(
    origins,
    directions,
    hits,
    spp,
    pixels,
    surfaces,
    environment,
    light_dir,
    ambient,
    lit,
    eye,
    plane,
    out,
    materials,
):
    """Shade every sample and average the samples of each pixel.

    origins, directions : (m*spp, 3) float32 rays;  hits : their closest hits (``tracer.Hits``: face, t,
    b1, b2; face -1 on a miss);  pixels : (m,) int64 the pixel of each group of spp rays, where its mean is
    written (the others are left as they are);  surfaces : a bundles.Surfaces
    environment : (h, w, 3) float32 equirectangular; light_dir : (3,) float64 travel direction
    eye, plane : the camera's eye (3,) float64 and a bundles.ImagePlane of the tile, for the ink
    out : bundles.Channels of n pixels: its color (n, 3) float32, the displayed color in [0, 1] (the other
    channels are :func:`record_surfaces`').
    materials : bundles.Materials, the materials beyond plain; None where every face is plain, and then their
    passes are not compiled (numba prunes a branch on an argument that is None). A material with bands is lit
    in that many flat bands (toon shading); one with an outline is inked where ``materials.ink`` has ink at the
    hit's pixel of the painting seen from the pixel's own eye, on the surface at that distance.

    A block of pixels at a time, in passes (the sky, the surfaces, their light, their textures, the rare
    materials, the means), each a short loop: the CPU overlaps the iterations of a short loop, whose loads wait
    on one another (the face, then its corners, then the texels), where one long loop ran sample after sample;
    and the arithmetic of the sky and of the light runs on contiguous columns without a branch, which the
    compiler vectorizes (the same operations, so the same bits). The scattered reads (a hit's corners, a lookup's
    texels) are asked for a loop before the one that reads them (``prefetch``): then many wait on memory at once.
    """
    face, t, b1, b2 = hits.face, hits.t, hits.b1, hits.b2
    normals, colors, uv, texture_id = surfaces.normals, surfaces.colors, surfaces.uv, surfaces.texture_id
    texels, texture_offset = surfaces.texels, surfaces.texture_offset
    texture_width, texture_height = surfaces.texture_width, surfaces.texture_height
    face_material = surfaces.face_material
    out_color = out.color
    n_pix = len(pixels)
    env_h = environment.shape[0]
    env_w = environment.shape[1]
    env_flat = environment.reshape(env_h * env_w, 3)
    inv_spp = 1.0 / spp
    panorama = env_w * env_h > 1
    lx = light_dir[0]
    ly = light_dir[1]
    lz = light_dir[2]
    ex = eye[0]
    ey = eye[1]
    ez = eye[2]
    side = 0
    inked = False
    if materials is not None:
        inked = materials.ink.any
    per_pixel = inked and (plane.projection == EQUIRECT or plane.half_ipd != 0.0)  # each pixel's own eye
    block = 256  # pixels
    size = block * spp
    # one block's samples, by sample: colour so far (r, g, b) and the light's factor on it; texture coordinates
    rgbk = np.empty((size, 4))
    coords = np.empty((size, 2))
    # the misses that look into the panorama: which sample, their direction, where they look
    sky = np.empty(size, np.int64)
    sky_dx = np.empty(size, np.float32)
    sky_dy = np.empty(size, np.float32)
    sky_dz = np.empty(size, np.float32)
    sky_x = np.empty(size)
    sky_y = np.empty(size)
    # the hits: which sample, face, barycentric weights, ray direction, normal, the light's factor
    hit = np.empty(size, np.int64)
    hit_face = np.empty(size, np.int64)
    hit_w0 = np.empty(size)
    hit_w1 = np.empty(size, np.float32)
    hit_w2 = np.empty(size, np.float32)
    hit_dx = np.empty(size, np.float32)
    hit_dy = np.empty(size, np.float32)
    hit_dz = np.empty(size, np.float32)
    hit_nx = np.empty(size)
    hit_ny = np.empty(size)
    hit_nz = np.empty(size)
    hit_k = np.empty(size)
    textured = np.empty(size, np.int64)  # the samples on a textured face, and the face's texture
    textures = np.empty(size, np.int64)
    # the texels each lookup reads and their weights (_bilinear_site): the sky's, then the textures'
    sites = np.empty((size, 4), np.int64)
    weights = np.empty((size, 2))
    special = np.empty(size, np.int64)  # the hits (their index among hits) on a material beyond plain
    for first in range(0, n_pix, block):
        last = min(first + block, n_pix)
        base = first * spp
        end = last * spp
        # ---- misses: the environment, equirectangular (a NaN ray sees black) ----
        n_sky = 0
        for s in range(base, end):
            f = face[s]
            if f >= 0:  # the hits' corners, read two passes on
                prefetch(colors, 9 * f)
                prefetch(uv, 6 * f)
                prefetch(normals, 9 * f)
            else:
                q = s - base
                dx = directions[s, 0]
                dy = directions[s, 1]
                dz = directions[s, 2]
                rgbk[q, 3] = 1.0
                if not (dx == dx and dy == dy and dz == dz):
                    rgbk[q, 0] = rgbk[q, 1] = rgbk[q, 2] = 0.0
                elif panorama:
                    sky[n_sky] = q
                    sky_dx[n_sky] = dx
                    sky_dy[n_sky] = dy
                    sky_dz[n_sky] = dz
                    n_sky += 1
                else:
                    rgbk[q, 0] = env_flat[0, 0]
                    rgbk[q, 1] = env_flat[0, 1]
                    rgbk[q, 2] = env_flat[0, 2]
        for i in range(n_sky):  # vectorized
            dx = sky_dx[i]
            dy = sky_dy[i]
            dz = sky_dz[i]
            lon = fast_atan2(dx, -dz)
            lat = 0.5 * math.pi - fast_atan2(dy, math.sqrt(dx * dx + dz * dz))
            sky_x[i] = (lon / (2.0 * math.pi) + 0.5) * env_w
            sky_y[i] = lat / math.pi * env_h
        for i in range(n_sky):  # where each reads: its texels asked for, read in the next loop
            k00, k01, k10, k11, tx, ty = _bilinear_site(0, env_w, env_h, sky_x[i], sky_y[i], False)
            prefetch(env_flat, 3 * k00)
            prefetch(env_flat, 3 * k10)
            sites[i, 0] = k00
            sites[i, 1] = k01
            sites[i, 2] = k10
            sites[i, 3] = k11
            weights[i, 0] = tx
            weights[i, 1] = ty
        for i in range(n_sky):
            q = sky[i]
            r, g, b = _bilinear_mix(
                env_flat, sites[i, 0], sites[i, 1], sites[i, 2], sites[i, 3], weights[i, 0], weights[i, 1]
            )
            rgbk[q, 0] = r
            rgbk[q, 1] = g
            rgbk[q, 2] = b
        # ---- hits: the corners' colour and texture coordinates ----
        n_hit = 0
        n_textured = 0
        n_special = 0
        for s in range(base, end):
            f = face[s]
            if f < 0:
                continue
            q = s - base
            w1 = b1[s]
            w2 = b2[s]
            w0 = 1.0 - w1 - w2
            r, g, b, u, v = _corners(colors, uv, f, w0, w1, w2)
            rgbk[q, 0] = r
            rgbk[q, 1] = g
            rgbk[q, 2] = b
            coords[q, 0] = u
            coords[q, 1] = v
            tid = texture_id[f]
            if tid >= 0:
                textured[n_textured] = q
                textures[n_textured] = tid
                n_textured += 1
            if face_material[f] > 0:
                special[n_special] = n_hit
                n_special += 1
            hit[n_hit] = q
            hit_face[n_hit] = f
            hit_w0[n_hit] = w0
            hit_w1[n_hit] = w1
            hit_w2[n_hit] = w2
            hit_dx[n_hit] = directions[s, 0]
            hit_dy[n_hit] = directions[s, 1]
            hit_dz[n_hit] = directions[s, 2]
            n_hit += 1
        # ---- the light: the normal at each hit, then its length and the light on it (two-sided: on the side
        # the ray sees), vectorized; a material beyond plain may be unlit or toon (below) ----
        if lit:
            for i in range(n_hit):
                hit_nx[i], hit_ny[i], hit_nz[i] = _interpolated(normals, hit_face[i], hit_w0[i], hit_w1[i], hit_w2[i])
            for i in range(n_hit):  # vectorized
                nx, ny, nz = _unit(hit_nx[i], hit_ny[i], hit_nz[i])
                hit_nx[i] = nx
                hit_ny[i] = ny
                hit_nz[i] = nz
                hit_k[i] = ambient + (1.0 - ambient) * _lambert(nx, ny, nz, hit_dx[i], hit_dy[i], hit_dz[i], lx, ly, lz)
        if materials is not None and lit:
            for i in range(n_special):
                h = special[i]
                mat = face_material[hit_face[h]]
                if materials.material_unlit[mat]:
                    hit_k[h] = 1.0
                elif materials.material_bands[mat] > 0:
                    # toon: the lit side in flat bands, the last one full light
                    lambert = _lambert(hit_nx[h], hit_ny[h], hit_nz[h], hit_dx[h], hit_dy[h], hit_dz[h], lx, ly, lz)
                    if lambert > 0.0:
                        bands = materials.material_bands[mat]
                        lambert = min(math.floor(lambert * bands) + 1.0, bands) / bands
                    hit_k[h] = ambient + (1.0 - ambient) * lambert
        for i in range(n_hit):
            rgbk[hit[i], 3] = hit_k[i] if lit else 1.0  # unlit: the albedo as it is (a product by 1 changes no bit)
        # ---- the textures, times the corners' colour: where each lookup reads, then the reads ----
        for i in range(n_textured):
            q = textured[i]
            tid = textures[i]
            k00, k01, k10, k11, tx, ty = _texel_site(
                texture_offset[tid], texture_width[tid], texture_height[tid], coords[q, 0], coords[q, 1]
            )
            prefetch(texels, 3 * k00)  # the texels' two rows, read in the next loop
            prefetch(texels, 3 * k10)
            sites[i, 0] = k00
            sites[i, 1] = k01
            sites[i, 2] = k10
            sites[i, 3] = k11
            weights[i, 0] = tx
            weights[i, 1] = ty
        for i in range(n_textured):
            q = textured[i]
            tr, tg, tb = _texel_mix(
                texels, sites[i, 0], sites[i, 1], sites[i, 2], sites[i, 3], weights[i, 0], weights[i, 1]
            )
            rgbk[q, 0] *= tr
            rgbk[q, 1] *= tg
            rgbk[q, 2] *= tb
        # ---- emission (glTF's emissiveFactor, times its texture): added after the light; then the ink ----
        if materials is not None:  # none in most scenes
            for i in range(n_special):
                q = hit[special[i]]
                s = base + q
                mat = face_material[face[s]]
                k = rgbk[q, 3]
                r = rgbk[q, 0] * k
                g = rgbk[q, 1] * k
                b = rgbk[q, 2] * k
                er = materials.material_emission[mat, 0]
                eg = materials.material_emission[mat, 1]
                eb = materials.material_emission[mat, 2]
                etid = materials.material_emission_texture[mat]
                if etid >= 0:
                    tw = texture_width[etid]
                    th = texture_height[etid]
                    tr, tg, tb = texel_color(texels, texture_offset[etid], tw, th, coords[q, 0], coords[q, 1])
                    er *= tr
                    eg *= tg
                    eb *= tb
                r += er
                g += eg
                b += eb
                if inked and materials.material_outline[mat] > 0.0:
                    if per_pixel:
                        col, row = tile_pixel(plane, pixels[s // spp])
                        side, col, row = locate(plane, col, row)
                        rx, ry, rz, _, _, _, _, _, _ = centre_frame(plane, col, row)
                        ex = eye[0] + side * plane.half_ipd * rx
                        ey = eye[1] + side * plane.half_ipd * ry
                        ez = eye[2] + side * plane.half_ipd * rz
                    ts = t[s]
                    hx = origins[s, 0] + ts * directions[s, 0]
                    hy = origins[s, 1] + ts * directions[s, 1]
                    hz = origins[s, 2] + ts * directions[s, 2]
                    ink = 1.0 - materials.material_outline[mat] * _ink_at(
                        materials.ink, plane, side, ex, ey, ez, hx, hy, hz
                    )
                    r *= ink
                    g *= ink
                    b *= ink
                rgbk[q, 0] = r
                rgbk[q, 1] = g
                rgbk[q, 2] = b
                rgbk[q, 3] = 1.0
        # ---- each pixel's mean ----
        for m in range(first, last):
            pix = pixels[m]
            acc_r = acc_g = acc_b = 0.0
            for s in range(m * spp, (m + 1) * spp):
                q = s - base
                k = rgbk[q, 3]
                acc_r += min(max(rgbk[q, 0] * k, 0.0), 1.0)
                acc_g += min(max(rgbk[q, 1] * k, 0.0), 1.0)
                acc_b += min(max(rgbk[q, 2] * k, 0.0), 1.0)
            out_color[pix, 0] = acc_r * inv_spp
            out_color[pix, 1] = acc_g * inv_spp
            out_color[pix, 2] = acc_b * inv_spp


@jit
def record_surfaces(origins, directions, hits, spp, pixels, surfaces, eye, plane, z_max, out, need):
    """The channels beside colour, a pass of its own that only a painting reading them runs (in ``shade``'s
    loop they cost every painting a fifth of its shading, and its compile a sixth): per pixel, the mean over its
    samples of the view depth ``(X - eye_ij) . f_ij`` (camera.py; ``z_max`` on a miss), the unit shading normal
    (a miss adds nothing), the unit ray direction (the mean direction made unit; a NaN ray adds nothing), the
    geometric normal (the triangle's own, on the side of the shading normal), the unlit colour (a miss adds
    nothing; a pixel all sky has the sky's colour, from ``out.color``, which shade wrote first), the texture
    coordinates and the world point (NaN if any sample saw the sky); the object and the material of its first
    sample (-1: the sky). Arguments as :func:`shade`'s, and ``z_max``; ``need`` (bundles.Records) says which of
    these channels to write.
    """
    face, t, b1, b2 = hits.face, hits.t, hits.b1, hits.b2
    triangles, normals = surfaces.triangles, surfaces.normals
    inv_spp = 1.0 / spp
    # each pixel's eye and f_ij, for depth: one for the whole image on a mono image plane
    _, _, _, _, _, _, fx, fy, fz = centre_frame(plane, 0, 0)
    ex = eye[0]
    ey = eye[1]
    ez = eye[2]
    per_pixel = need.depth and (plane.projection == EQUIRECT or plane.half_ipd != 0.0)
    for m in range(len(pixels)):
        pix = pixels[m]
        if per_pixel:
            col, row = tile_pixel(plane, pix)
            side, col, row = locate(plane, col, row)
            rx, ry, rz, _, _, _, fx, fy, fz = centre_frame(plane, col, row)
            ex = eye[0] + side * plane.half_ipd * rx
            ey = eye[1] + side * plane.half_ipd * ry
            ez = eye[2] + side * plane.half_ipd * rz
        front = face[m * spp]  # an index does not average: the first sample's
        if need.object:
            out.object[pix] = surfaces.face_object[front] if front >= 0 else -1.0
        if need.material:
            out.material[pix] = surfaces.face_material[front] if front >= 0 else -1.0
        acc_z = acc_nx = acc_ny = acc_nz = acc_dx = acc_dy = acc_dz = 0.0
        gx = gy = gz = ar = ag = ab = u = v = px = py = pz = 0.0
        misses = 0
        for s in range(m * spp, (m + 1) * spp):
            f = face[s]
            dx = directions[s, 0]
            dy = directions[s, 1]
            dz = directions[s, 2]
            if need.direction and dx == dx and dy == dy and dz == dz:
                acc_dx += dx
                acc_dy += dy
                acc_dz += dz
            if f < 0:
                acc_z += z_max
                misses += 1
                continue
            ts = t[s]
            hx = origins[s, 0] + ts * dx
            hy = origins[s, 1] + ts * dy
            hz = origins[s, 2] + ts * dz
            if need.depth:
                acc_z += (hx - ex) * fx + (hy - ey) * fy + (hz - ez) * fz
            w1 = b1[s]
            w2 = b2[s]
            w0 = 1.0 - w1 - w2
            nx, ny, nz = _interpolated(normals, f, w0, w1, w2)
            if need.normal:
                ux, uy, uz = _unit(nx, ny, nz)
                acc_nx += ux
                acc_ny += uy
                acc_nz += uz
            if need.geometric:
                ax = triangles[f, 1, 0] - triangles[f, 0, 0]
                ay = triangles[f, 1, 1] - triangles[f, 0, 1]
                az = triangles[f, 1, 2] - triangles[f, 0, 2]
                bx = triangles[f, 2, 0] - triangles[f, 0, 0]
                by = triangles[f, 2, 1] - triangles[f, 0, 1]
                bz = triangles[f, 2, 2] - triangles[f, 0, 2]
                cx = ay * bz - az * by
                cy = az * bx - ax * bz
                cz = ax * by - ay * bx
                length = math.sqrt(cx * cx + cy * cy + cz * cz)
                side = 0.0 if length == 0.0 else (-1.0 if cx * nx + cy * ny + cz * nz < 0.0 else 1.0) / length
                gx += cx * side
                gy += cy * side
                gz += cz * side
            if need.albedo or need.uv:
                r, g, b, su, sv = _albedo(
                    surfaces.colors,
                    surfaces.uv,
                    surfaces.texture_id,
                    surfaces.texels,
                    surfaces.texture_offset,
                    surfaces.texture_width,
                    surfaces.texture_height,
                    f,
                    w0,
                    w1,
                    w2,
                )
                ar += r
                ag += g
                ab += b
                u += su
                v += sv
            px += hx
            py += hy
            pz += hz
        if need.depth:
            out.depth[pix] = acc_z * inv_spp
        if need.normal:
            out.normal[pix, 0] = acc_nx * inv_spp
            out.normal[pix, 1] = acc_ny * inv_spp
            out.normal[pix, 2] = acc_nz * inv_spp
        if need.direction:
            dlen = math.sqrt(acc_dx * acc_dx + acc_dy * acc_dy + acc_dz * acc_dz)
            inv = 1.0 / dlen if dlen > 0.0 else 0.0
            out.direction[pix, 0] = acc_dx * inv
            out.direction[pix, 1] = acc_dy * inv
            out.direction[pix, 2] = acc_dz * inv
        if need.geometric:
            out.geometric[pix, 0] = gx * inv_spp
            out.geometric[pix, 1] = gy * inv_spp
            out.geometric[pix, 2] = gz * inv_spp
        if need.albedo and misses == spp:  # all sky: its colour, as shade drew it
            out.albedo[pix, 0] = out.color[pix, 0]
            out.albedo[pix, 1] = out.color[pix, 1]
            out.albedo[pix, 2] = out.color[pix, 2]
        elif need.albedo:  # the surface's share (the sky's samples add nothing)
            out.albedo[pix, 0] = ar * inv_spp
            out.albedo[pix, 1] = ag * inv_spp
            out.albedo[pix, 2] = ab * inv_spp
        if need.uv:
            out.uv[pix, 0] = u * inv_spp
            out.uv[pix, 1] = v * inv_spp
        if need.position:
            nan = math.nan if misses else 0.0  # the sky has no point
            out.position[pix, 0] = px * inv_spp + nan
            out.position[pix, 1] = py * inv_spp + nan
            out.position[pix, 2] = pz * inv_spp + nan
