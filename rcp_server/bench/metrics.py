"""Image error against a reference: PSNR and SSIM, over the whole image or a mask (the screen-edge band),
and the bilinear upscaling that brings a smaller render to the reference's size.

Images are (h, w, 3) float in [0, 1] (data range 1).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter

from ..painting.imagespace import bilinear

PSNR_CAP = 100.0  # dB, reported for identical images (an infinite PSNR does not chart or serialise)
SSIM_WINDOW = 7  # pixels, a uniform window as scikit-image's default


def edge_band(height: int, width: int, fraction: float = 0.08) -> np.ndarray:
    """(h, w) bool: the pixels within ``fraction`` of the image's size of any screen edge."""
    bx = max(1, round(fraction * width))
    by = max(1, round(fraction * height))
    j, i = np.mgrid[0:height, 0:width]
    return (i < bx) | (i >= width - bx) | (j < by) | (j >= height - by)


def psnr(image: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Peak signal-to-noise ratio in dB over the pixels of ``mask`` (all by default), capped at PSNR_CAP."""
    err = (np.asarray(image, np.float64) - np.asarray(reference, np.float64)) ** 2
    mse = float(err[mask].mean() if mask is not None else err.mean())
    return PSNR_CAP if mse <= 10.0 ** (-PSNR_CAP / 10.0) else float(-10.0 * np.log10(mse))


def ssim_map(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Structural similarity per pixel, (h, w) float64, the mean over channels (Wang et al. 2004 with a
    uniform 7x7 window and sample covariances, as scikit-image computes it; borders reflect)."""
    a = np.asarray(image, np.float64)
    b = np.asarray(reference, np.float64)
    size = (SSIM_WINDOW, SSIM_WINDOW, 1)
    n = SSIM_WINDOW * SSIM_WINDOW
    cov = n / (n - 1.0)

    def mean(x):
        return uniform_filter(x, size, mode="reflect")

    ma, mb = mean(a), mean(b)
    va = cov * (mean(a * a) - ma * ma)
    vb = cov * (mean(b * b) - mb * mb)
    vab = cov * (mean(a * b) - ma * mb)
    c1, c2 = 0.01**2, 0.03**2
    s = ((2 * ma * mb + c1) * (2 * vab + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
    return s.mean(axis=2)


def ssim(image: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean structural similarity over the pixels of ``mask`` (all by default); 1 is identical."""
    s = ssim_map(image, reference)
    return float(s[mask].mean() if mask is not None else s.mean())


def upscale(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear resize of (h, w, c) to (height, width, c), pixel centres aligned, edges clamped: float32."""
    h, w = image.shape[:2]
    if (h, w) == (height, width):
        return image
    j, i = np.mgrid[0:height, 0:width]
    x = (i.ravel() + 0.5) * (w / width) - 0.5
    y = (j.ravel() + 0.5) * (h / height) - 0.5
    return bilinear(image, x, y, "clamp").reshape(height, width, -1).astype(np.float32)
