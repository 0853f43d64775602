"""Seeded random numbers keyed by pixel, so that any tile draws exactly the numbers the full image does.

Numbers come from a counter-based hash of ``(seed, stream, i, j, k)`` rather than from a generator's
sequence: the value for a pixel never depends on which other pixels were drawn before it.
"""

from __future__ import annotations

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)

# independent streams of the hash, one per use
STREAM_JITTER_X = 1
STREAM_JITTER_Y = 2
STREAM_STRATA = 3
STREAM_NOISE = 4
STREAM_SURFACE = 5  # surface noise: keyed by a cell of world space, not a pixel
STREAM_OBJECT = 6  # the cubist mapping: keyed by an object


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finalizer: a bijection on uint64 with full avalanche."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return np.asarray(x ^ (x >> np.uint64(31)))  # an array for numpy's stubs too (no copy)


def uniform(seed: int, stream: int, *keys: np.ndarray) -> np.ndarray:
    """Uniform floats in [0, 1), one per element of the broadcast ``keys`` (non-negative integers)."""
    with np.errstate(over="ignore"):
        h = _mix(np.asarray(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) * _GOLDEN + np.uint64(stream)))
        for key in np.broadcast_arrays(*[np.asarray(k, dtype=np.uint64) for k in keys]):
            h = _mix(h ^ (key + _GOLDEN + (h << np.uint64(6)) + (h >> np.uint64(2))))
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def stratified_offsets(seed: int, i: np.ndarray, j: np.ndarray, spp: int) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel offsets ``(xi, eta)`` for ``spp`` samples of each pixel ``(i, j)``: two (n, spp) float64.

    One sample sits at the pixel centre. More samples are Latin-hypercube stratified (each of the spp
    columns and each of the spp rows of the pixel holds one sample), jittered inside their stratum.
    """
    if spp == 1:
        half = np.full((i.size, 1), 0.5)
        return half, half.copy()
    k = np.arange(spp, dtype=np.uint64)[None, :]
    ii, jj = i[:, None], j[:, None]
    # a per-pixel random permutation pairs x strata with y strata
    perm = np.argsort(uniform(seed, STREAM_STRATA, ii, jj, k), axis=1)
    xi = (k.astype(np.float64) + uniform(seed, STREAM_JITTER_X, ii, jj, k)) / spp
    eta = (perm + uniform(seed, STREAM_JITTER_Y, ii, jj, k)) / spp
    return xi, eta


def noise_vectors(seed: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """A fixed random vector per pixel, uniform in the cube [-1, 1]^3: (n, 3) float64."""
    axis = np.arange(3, dtype=np.uint64)[None, :]
    return 2.0 * uniform(seed, STREAM_NOISE, i[:, None], j[:, None], axis) - 1.0
