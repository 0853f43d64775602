"""The projections, compiled: where a pixel's camera looks before displacement, and where a direction lands
in the image. ``camera.py`` states the conventions and holds the numpy twin of each function here
(``eye_pixels``, ``directions_at``, ``pixel_frames``, ``project``); ``tests/engine/test_projection.py``
checks that they agree. Every kernel that places a pixel goes through these, so a projection is added
here and in ``camera.py``, nowhere else.
"""

from __future__ import annotations

import math

import numba

PERSPECTIVE, EQUIRECT = 0, 1  # camera.PROJECTIONS, in order
MONO, TOP_BOTTOM, SIDE_BY_SIDE = 0, 1, 2  # camera.STEREO, in order


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


@numba.njit(inline="always")
def locate(plane, i, j):
    """Pixel ``(i, j)`` of the painting (absolute) -> ``(side, i, j)``: its eye (-1 left, 1 right, 0 mono) and
    where it lies in that eye's image."""
    if plane.layout == TOP_BOTTOM:
        return (-1, i, j) if j < plane.eye_height else (1, i, j - plane.eye_height)
    if plane.layout == SIDE_BY_SIDE:
        return (-1, i, j) if i < plane.eye_width else (1, i - plane.eye_width, j)
    return 0, i, j


@numba.njit(inline="always")
def tile_pixel(plane, pix):
    """The tile's pixel ``pix`` (row-major) -> its absolute ``(i, j)`` in the painting."""
    row = pix // plane.width
    return plane.x0 + pix - row * plane.width, plane.y0 + row


@numba.njit(inline="always")
def centre_frame(plane, i, j):
    """The local frame ``(r_ij, u_ij, f_ij)`` at the centre of pixel ``(i, j)`` of an eye's image, as nine
    numbers; the centre's target offset is ``f_ij`` itself on the sphere."""
    b = plane.basis
    if plane.projection == EQUIRECT:
        cp = plane.columns[i, 0]
        sp = plane.columns[i, 1]
        ct = plane.rows[j, 0]
        st = plane.rows[j, 1]
        rx = cp * b[0, 0] - sp * b[2, 0]
        ry = cp * b[0, 1] - sp * b[2, 1]
        rz = cp * b[0, 2] - sp * b[2, 2]
        fx = ct * sp * b[0, 0] + st * b[1, 0] + ct * cp * b[2, 0]
        fy = ct * sp * b[0, 1] + st * b[1, 1] + ct * cp * b[2, 1]
        fz = ct * sp * b[0, 2] + st * b[1, 2] + ct * cp * b[2, 2]
        return rx, ry, rz, ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx, fx, fy, fz
    return b[0, 0], b[0, 1], b[0, 2], b[1, 0], b[1, 1], b[1, 2], b[2, 0], b[2, 1], b[2, 2]


@numba.njit(inline="always")
def target_offset(plane, x, y):
    """``d = P_p - eye_ij`` at the continuous point ``(x, y)`` of an eye's image (pixel ``(i, j)`` spans
    ``[i, i + 1) x [j, j + 1)``): the image plane's point, or the unit sphere's."""
    b = plane.basis
    if plane.projection == EQUIRECT:
        # divisions by the invariants written apart, so that they leave the caller's loop
        phi = (x * (2.0 / plane.eye_width) - 1.0) * math.pi
        theta = (1.0 - y * (2.0 / plane.eye_height)) * (0.5 * math.pi)
        cp = math.cos(phi)
        sp = math.sin(phi)
        ct = math.cos(theta)
        st = math.sin(theta)
        return (
            ct * sp * b[0, 0] + st * b[1, 0] + ct * cp * b[2, 0],
            ct * sp * b[0, 1] + st * b[1, 1] + ct * cp * b[2, 1],
            ct * sp * b[0, 2] + st * b[1, 2] + ct * cp * b[2, 2],
        )
    sx = (x * (2.0 / plane.eye_width) - 1.0) * (plane.aspect * plane.tan_half)
    ty = (1.0 - y * (2.0 / plane.eye_height)) * plane.tan_half
    return (
        b[2, 0] + sx * b[0, 0] + ty * b[1, 0],
        b[2, 1] + sx * b[0, 1] + ty * b[1, 1],
        b[2, 2] + sx * b[0, 2] + ty * b[1, 2],
    )


@numba.njit(inline="always")
def to_pixel(plane, side, dx, dy, dz, exact=True):
    """The inverse map: where direction ``d`` from the eye on ``side`` crosses that eye's image, as continuous
    coordinates of the painting with pixel centres on the integers, and whether it does (not behind a
    perspective camera, not zero or NaN): ``(x, y, ok)``. ``exact=False``: on the sphere within 1e-5 rad
    (``fast_atan2``), for finding which pixels lie around a direction (a 4096-wide panorama's pixel is 1.5e-3
    rad), at a third of the cost."""
    b = plane.basis
    dr = dx * b[0, 0] + dy * b[0, 1] + dz * b[0, 2]
    du = dx * b[1, 0] + dy * b[1, 1] + dz * b[1, 2]
    df = dx * b[2, 0] + dy * b[2, 1] + dz * b[2, 2]
    if plane.projection == EQUIRECT:
        length = math.sqrt(dr * dr + du * du + df * df)
        if not length > 0.0:
            return 0.0, 0.0, False
        if exact:
            longitude = math.atan2(dr, df)
            latitude = math.asin(min(max(du / length, -1.0), 1.0))
        else:
            longitude = fast_atan2(dr, df)
            latitude = fast_atan2(du, math.sqrt(dr * dr + df * df))
        x = (longitude / (2.0 * math.pi) + 0.5) * plane.eye_width - 0.5
        y = (0.5 - latitude / math.pi) * plane.eye_height - 0.5
    else:
        if not df > 0.0:
            return 0.0, 0.0, False
        x = (dr / (df * plane.aspect * plane.tan_half) + 1.0) * (0.5 * plane.eye_width) - 0.5
        y = (1.0 - du / (df * plane.tan_half)) * (0.5 * plane.eye_height) - 0.5
    if side > 0:
        if plane.layout == SIDE_BY_SIDE:
            x += plane.eye_width
        elif plane.layout == TOP_BOTTOM:
            y += plane.eye_height
    return x, y, math.isfinite(x) and math.isfinite(y)
