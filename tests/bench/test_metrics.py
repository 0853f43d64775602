"""Error measures: PSNR, SSIM (against scikit-image where installed), the edge band, upscaling."""

import numpy as np
import pytest

from rcp_server.bench.metrics import PSNR_CAP, edge_band, psnr, ssim, ssim_map, upscale


def test_psnr_of_a_known_error_and_of_identical_images():
    a = np.zeros((4, 6, 3))
    assert psnr(a, a) == PSNR_CAP
    assert psnr(a + 0.1, a) == pytest.approx(20.0)
    mask = np.zeros((4, 6), bool)
    mask[0] = True
    b = a.copy()
    b[1:] = 0.5
    assert psnr(b, a, mask) == PSNR_CAP and psnr(b, a) < 10


def test_ssim_is_one_for_identical_images_and_agrees_with_scikit_image():
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 1, (24, 30, 3))
    b = np.clip(a + rng.normal(0, 0.1, a.shape), 0, 1)
    assert ssim(a, a) == pytest.approx(1.0)
    assert ssim(b, a) < 0.96 and ssim(1.0 - a, a) < 0.0
    metrics = pytest.importorskip("skimage.metrics")
    ours = ssim_map(b, a)[3:-3, 3:-3].mean()  # scikit-image leaves out the border half-window
    theirs = metrics.structural_similarity(b, a, channel_axis=2, data_range=1.0)
    assert ours == pytest.approx(theirs, abs=1e-6)


def test_edge_band_is_the_outer_fraction_of_each_side():
    band = edge_band(50, 100, 0.1)
    assert band[:5].all() and band[-5:].all() and band[:, :10].all() and band[:, -10:].all()
    assert not band[5:-5, 10:-10].any()


def test_upscale_keeps_a_linear_ramp_linear_and_a_full_size_image_as_is():
    ramp = np.linspace(0, 1, 8, dtype=np.float32)[None, :, None].repeat(4, 0).repeat(3, 2)
    big = upscale(ramp, 16, 8)
    assert big.shape == (8, 16, 3)
    inner = big[:, 1:-1, 0]
    np.testing.assert_allclose(np.diff(inner, axis=1), np.diff(inner, axis=1)[0, 0], atol=1e-6)
    assert upscale(ramp, 8, 4) is ramp
