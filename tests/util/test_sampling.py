"""Seeded, pixel-keyed sampling: reproducible, stratified, independent of which pixels are drawn."""

import math

import numpy as np
import pytest

from rcp_server.camera.camera import Region
from rcp_server.util.sampling import noise_vectors, stratified_offsets, uniform


def _pixels(width=24, height=16):
    return Region(width, height).pixel_coords()


def test_same_seed_gives_the_same_offsets():
    i, j = _pixels()
    a = stratified_offsets(7, i, j, 8)
    b = stratified_offsets(7, i, j, 8)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(noise_vectors(7, i, j), noise_vectors(7, i, j))


def test_different_seeds_give_different_offsets_everywhere():
    i, j = _pixels()
    xi0, eta0 = stratified_offsets(0, i, j, 4)
    xi1, eta1 = stratified_offsets(1, i, j, 4)
    # not just somewhere: every single jittered value changes
    assert np.all(xi0 != xi1) and np.all(eta0 != eta1)
    assert np.all(noise_vectors(0, i, j) != noise_vectors(1, i, j))


def test_one_sample_sits_at_the_pixel_centre():
    i, j = _pixels()
    for seed in (0, 3):
        xi, eta = stratified_offsets(seed, i, j, 1)
        assert xi.shape == eta.shape == (i.size, 1)
        assert np.all(xi == 0.5) and np.all(eta == 0.5)


@pytest.mark.parametrize("spp", [2, 3, 4, 9, 16])
def test_latin_hypercube_one_sample_per_column_and_row_stratum(spp):
    i, j = _pixels()
    xi, eta = stratified_offsets(11, i, j, spp)
    assert xi.shape == eta.shape == (i.size, spp)
    assert np.all((xi >= 0) & (xi < 1) & (eta >= 0) & (eta < 1))
    strata = np.arange(spp)
    np.testing.assert_array_equal(np.sort(np.floor(xi * spp), axis=1), np.broadcast_to(strata, xi.shape))
    np.testing.assert_array_equal(np.sort(np.floor(eta * spp), axis=1), np.broadcast_to(strata, eta.shape))
    # the pairing of x and y strata is shuffled per pixel, not the same diagonal everywhere
    # (xi's k-th sample is in column k, so eta's strata are the pairing permutation)
    permutations = np.unique(np.floor(eta * spp).astype(int), axis=0)
    assert len(permutations) >= min(math.factorial(spp), 20)


def test_offsets_of_a_pixel_do_not_depend_on_the_other_pixels_drawn():
    full = Region(30, 20)
    tile = Region(30, 20, 11, 7, 5, 4)
    fi, fj = full.pixel_coords()
    ti, tj = tile.pixel_coords()
    index = tj * 30 + ti
    for spp in (1, 5):
        fxi, feta = stratified_offsets(5, fi, fj, spp)
        txi, teta = stratified_offsets(5, ti, tj, spp)
        np.testing.assert_array_equal(txi, fxi[index])
        np.testing.assert_array_equal(teta, feta[index])
    np.testing.assert_array_equal(noise_vectors(5, ti, tj), noise_vectors(5, fi, fj)[index])
    # a single pixel alone, and the pixels in reverse order
    one = stratified_offsets(5, ti[3:4], tj[3:4], 5)
    np.testing.assert_array_equal(one[0], stratified_offsets(5, fi, fj, 5)[0][index[3:4]])
    rev = stratified_offsets(5, fi[::-1], fj[::-1], 5)
    np.testing.assert_array_equal(rev[1][::-1], stratified_offsets(5, fi, fj, 5)[1])


def test_uniform_is_in_unit_interval_and_roughly_uniform():
    k = np.arange(200_000)
    x = uniform(42, 9, k)
    assert x.min() >= 0.0 and x.max() < 1.0
    counts = np.histogram(x, bins=20, range=(0, 1))[0]
    # 10,000 expected per bin; 5 sigma is 500
    assert np.all(np.abs(counts - 10_000) < 500)
    # streams are independent of each other
    assert abs(np.corrcoef(x, uniform(42, 10, k))[0, 1]) < 0.02


def test_noise_vectors_fill_the_cube():
    i, j = _pixels(100, 100)
    v = noise_vectors(3, i, j)
    assert v.shape == (10_000, 3)
    assert v.min() >= -1.0 and v.max() < 1.0
    np.testing.assert_allclose(v.mean(axis=0), 0.0, atol=0.03)
    # the three components of a pixel are not the same number
    assert not np.any(v[:, 0] == v[:, 1]) and not np.any(v[:, 1] == v[:, 2])
