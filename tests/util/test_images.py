"""Encoding: the only place float images become uint8."""

import io

import numpy as np
import pytest
from PIL import Image

from rcp_server.util.images import encode, image_format, save, to_uint8


def _decode(data: bytes) -> np.ndarray:
    with Image.open(io.BytesIO(data)) as im:
        assert im.mode == "RGB"
        return np.asarray(im)


def test_to_uint8_rounds_to_nearest_and_clamps():
    image = np.array([[[0.0, 1.0, 0.5], [-3.0, 7.0, np.nan], [1 / 255, 0.5 / 255 - 1e-6, 254.5 / 255]]], np.float32)
    out = to_uint8(image)
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, [[[0, 255, 128], [0, 255, 0], [1, 0, 255]]])


def test_png_round_trip_is_exact():
    rng = np.random.default_rng(0)
    levels = rng.integers(0, 256, (24, 32, 3))
    image = (levels / 255.0).astype(np.float32)
    data = encode(image, "PNG")
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    np.testing.assert_array_equal(_decode(data), levels)


def test_jpeg_round_trip_is_close():
    y, x = np.mgrid[0:48, 0:64]
    image = np.stack([x / 63, y / 47, 0.5 + 0.25 * np.sin(x / 5.0)], axis=2).astype(np.float32)
    data = encode(image, "JPEG", quality=95)
    assert data[:3] == b"\xff\xd8\xff"
    decoded = _decode(data).astype(np.float64)
    assert decoded.shape == (48, 64, 3)
    assert np.abs(decoded - to_uint8(image)).mean() < 2.0
    # lower quality is smaller
    assert len(encode(image, "JPEG", quality=20)) < len(data)


@pytest.mark.parametrize("quality", [30, 70, 95])
def test_jpeg_keeps_full_resolution_color_at_every_quality(quality):
    from PIL import JpegImagePlugin

    image = np.random.default_rng(1).uniform(0, 1, (16, 16, 3)).astype(np.float32)
    with Image.open(io.BytesIO(encode(image, "JPEG", quality=quality))) as im:
        assert JpegImagePlugin.get_sampling(im) == 0  # 4:4:4


def test_save_picks_the_format_from_the_suffix(tmp_path):
    image = np.full((4, 6, 3), 0.25, np.float32)
    save(tmp_path / "a" / "x.PNG", image)
    save(tmp_path / "x.jpeg", image)
    with Image.open(tmp_path / "a" / "x.PNG") as im:
        assert im.format == "PNG" and im.size == (6, 4)
    with Image.open(tmp_path / "x.jpeg") as im:
        assert im.format == "JPEG"
    assert image_format("y.jpg") == "JPEG"
    with pytest.raises(ValueError, match=r"\.png"):
        image_format("y.tiff")
