"""Which pixels an iteration must paint again (the ``fast`` setting).

A pixel's ray is a function of what its mapping reads of ``I_{n-1}`` at that pixel (and of constants of
the painting: its camera, sample offsets and noise), and its new value a function of that ray. So a
pixel whose recorded inputs are bit for bit those of the iteration before gets the same ray and the same
value again: it keeps its value and costs nothing.

Colors are compared in quarters of a display level (``REUSE_LEVELS``, 10 bits; the paper's render target is
8-bit): a pixel whose color moved by less than that keeps its value too. That is the one approximation
here; ``rcp bench levels``, ``rcp bench agreement`` and ``tests/engine/test_fast.py`` measure what it changes.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .jit import jit

REUSE_LEVELS = 1023  # the color levels a kept pixel is compared in: a quarter of a display level (8 bits
# kept too much on fine textures seen close: 98.9% of the staircase hall's pixels within 2/255, 99.95% at 10 bits)


@numba.njit(inline="always")
def _bits(a):
    """A float32 channel of one or more columns as (n, k) int32 bits."""
    return a.reshape(a.shape[0], -1).view(np.int32)


@numba.njit(inline="always")
def _same(x, y, pix):
    """Row ``pix`` of two :func:`_bits` arrays equal (NaN equals the same NaN)."""
    for q in range(x.shape[1]):
        if x[pix, q] != y[pix, q]:
            return False
    return True


@numba.njit(inline="always")
def _copy_row(source, target, pix):
    a = source.reshape(source.shape[0], -1)
    b = target.reshape(target.shape[0], -1)
    for q in range(a.shape[1]):
        b[pix, q] = a[pix, q]


@jit
def changed_pixels(before, after, color, channels, color_levels, out):
    """Writes to the start of ``out`` the pixels whose channels differ between ``before`` and ``after``
    (bundles.Channels of n pixels), ascending, and returns how many.

    color : compare color;  channels : bundles.Records, the other channels to compare (the ones a mapping
    reads), as bits (NaN equals the same NaN); color as ``floor(c * color_levels + 0.5)``, or as bits when
    ``color_levels`` is 0.  out : (n,) int64.
    """
    n = out.shape[0]
    count = 0
    c0, c1 = before.color, after.color
    cb0, cb1 = _bits(c0), _bits(c1)
    z0, z1 = _bits(before.depth), _bits(after.depth)
    n0, n1 = _bits(before.normal), _bits(after.normal)
    d0, d1 = _bits(before.direction), _bits(after.direction)
    g0, g1 = _bits(before.geometric), _bits(after.geometric)
    o0, o1 = _bits(before.object), _bits(after.object)
    m0, m1 = _bits(before.material), _bits(after.material)
    a0, a1 = _bits(before.albedo), _bits(after.albedo)
    u0, u1 = _bits(before.uv), _bits(after.uv)
    p0, p1 = _bits(before.position), _bits(after.position)
    levels = np.float32(color_levels)
    for pix in range(n):
        same = True
        if color and color_levels > 0:
            for q in range(3):
                # floats, not ints: a NaN compares unequal (and so is painted again) instead of converting
                same = same and math.floor(c0[pix, q] * levels + 0.5) == math.floor(c1[pix, q] * levels + 0.5)
        elif color:
            same = _same(cb0, cb1, pix)
        same = same and (not channels.depth or _same(z0, z1, pix))
        same = same and (not channels.normal or _same(n0, n1, pix))
        same = same and (not channels.direction or _same(d0, d1, pix))
        same = same and (not channels.geometric or _same(g0, g1, pix))
        same = same and (not channels.object or _same(o0, o1, pix))
        same = same and (not channels.material or _same(m0, m1, pix))
        same = same and (not channels.albedo or _same(a0, a1, pix))
        same = same and (not channels.uv or _same(u0, u1, pix))
        same = same and (not channels.position or _same(p0, p1, pix))
        if not same:
            out[count] = pix
            count += 1
    return count


@jit
def carry(previous, out, painted, channels):
    """Copy every pixel not listed in ``painted`` (ascending) from ``previous`` to ``out`` (bundles.Channels of
    n pixels): the pixels an iteration keeps, written into the tile's other buffer rather than copying the
    whole state before painting over it. Color always; ``channels`` (bundles.Records): the others to copy.
    """
    n = out.color.shape[0]
    cursor = 0
    for pix in range(n):
        if cursor < len(painted) and painted[cursor] == pix:
            cursor += 1
            continue
        _copy_row(previous.color, out.color, pix)
        if channels.depth:
            _copy_row(previous.depth, out.depth, pix)
        if channels.normal:
            _copy_row(previous.normal, out.normal, pix)
        if channels.direction:
            _copy_row(previous.direction, out.direction, pix)
        if channels.geometric:
            _copy_row(previous.geometric, out.geometric, pix)
        if channels.object:
            _copy_row(previous.object, out.object, pix)
        if channels.material:
            _copy_row(previous.material, out.material, pix)
        if channels.albedo:
            _copy_row(previous.albedo, out.albedo, pix)
        if channels.uv:
            _copy_row(previous.uv, out.uv, pix)
        if channels.position:
            _copy_row(previous.position, out.position, pix)
