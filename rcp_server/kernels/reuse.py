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

import numpy as np

from .jit import jit

REUSE_LEVELS = 1023  # the color levels a kept pixel is compared in: a quarter of a display level (8 bits
# kept too much on fine textures seen close: 98.9% of the staircase hall's pixels within 2/255, 99.95% at 10 bits)


@jit
def changed_pixels(before, after, color, depth, normal, direction, color_levels, out):
    """Writes to the start of ``out`` the pixels whose channels differ between ``before`` and ``after``
    (bundles.Channels of n pixels), ascending, and returns how many.

    color, depth, normal, direction : compare that channel (the ones a mapping reads); depth, normal and
    direction compare as bits (NaN equals the same NaN); color as ``floor(c * color_levels + 0.5)``, or as
    bits when ``color_levels`` is 0.  out : (n,) int64.
    """
    n = out.shape[0]
    count = 0
    c0, c1 = before.color, after.color
    cb0, cb1 = c0.view(np.int32), c1.view(np.int32)
    z0, z1 = before.depth.view(np.int32), after.depth.view(np.int32)
    n0, n1 = before.normal.view(np.int32), after.normal.view(np.int32)
    d0, d1 = before.direction.view(np.int32), after.direction.view(np.int32)
    levels = np.float32(color_levels)
    for pix in range(n):
        same = True
        if color and color_levels > 0:
            for q in range(3):
                # floats, not ints: a NaN compares unequal (and so is painted again) instead of converting
                same = same and math.floor(c0[pix, q] * levels + 0.5) == math.floor(c1[pix, q] * levels + 0.5)
        elif color:
            same = cb0[pix, 0] == cb1[pix, 0] and cb0[pix, 1] == cb1[pix, 1] and cb0[pix, 2] == cb1[pix, 2]
        if same and depth:
            same = z0[pix] == z1[pix]
        if same and normal:
            same = n0[pix, 0] == n1[pix, 0] and n0[pix, 1] == n1[pix, 1] and n0[pix, 2] == n1[pix, 2]
        if same and direction:
            same = d0[pix, 0] == d1[pix, 0] and d0[pix, 1] == d1[pix, 1] and d0[pix, 2] == d1[pix, 2]
        if not same:
            out[count] = pix
            count += 1
    return count


@jit
def carry(previous, out, painted, depth, normal, direction):
    """Copy every pixel not listed in ``painted`` (ascending) from ``previous`` to ``out`` (bundles.Channels of
    n pixels): the pixels an iteration keeps, written into the tile's other buffer rather than copying the
    whole state before painting over it. Color always; depth, normal, direction: whether to copy that channel.
    """
    n = out.color.shape[0]
    cursor = 0
    for pix in range(n):
        if cursor < len(painted) and painted[cursor] == pix:
            cursor += 1
            continue
        for q in range(3):
            out.color[pix, q] = previous.color[pix, q]
        if depth:
            out.depth[pix] = previous.depth[pix]
        for q in range(3):
            if normal:
                out.normal[pix, q] = previous.normal[pix, q]
            if direction:
                out.direction[pix, q] = previous.direction[pix, q]
