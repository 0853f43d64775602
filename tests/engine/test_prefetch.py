"""``prefetch`` (``engine/kernels/prefetch.py``): a hint that changes no result, on arrays of any dtype and shape in
one kernel (LLVM's one prefetch function takes them all)."""

import numba
import numpy as np

from rcp_server.engine.kernels.prefetch import prefetch


@numba.njit
def _sum(texels, corners, weights, rows, hint):
    total = 0.0
    if hint:
        for k in rows:
            prefetch(texels, 3 * k)
            prefetch(corners, 9 * k)
            prefetch(weights, k)
    for k in rows:
        total += texels[k, 0] + corners[k, 1, 2] + weights[k]
    return total


def test_prefetch_changes_nothing_on_arrays_of_several_dtypes():
    rng = np.random.default_rng(0)
    texels = rng.integers(0, 256, (50, 3)).astype(np.uint8)
    corners = rng.normal(size=(50, 3, 3)).astype(np.float32)
    weights = rng.normal(size=50)
    rows = rng.integers(0, 50, 200)
    expected = sum(float(texels[k, 0]) + float(corners[k, 1, 2]) + weights[k] for k in rows)
    assert _sum(texels, corners, weights, rows, True) == _sum(texels, corners, weights, rows, False)
    assert abs(_sum(texels, corners, weights, rows, True) - expected) < 1e-9 * abs(expected)
