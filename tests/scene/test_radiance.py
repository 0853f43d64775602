"""Radiance .hdr panoramas: RGBE decoding (flat and run-length scanlines), refusals, the tonemap."""

import math

import numpy as np
import pytest

from rcp_server.cli import main
from rcp_server.painting.loop import paint
from rcp_server.scene.radiance import RadianceError, read_radiance, tonemap
from rcp_server.scene.scenefile import load_scene_file
from rcp_server.settings.params import PaintParams


def rgbe(radiance: np.ndarray) -> np.ndarray:
    """(h, w, 3) float -> (h, w, 4) uint8, the standard RGBE encoding (Ward's float2rgbe)."""
    top = radiance.max(axis=2)
    mantissa, exponent = np.frexp(top)
    scale = np.where(top > 1e-32, mantissa * 256.0 / np.where(top > 0, top, 1.0), 0.0)
    out = np.zeros(radiance.shape[:2] + (4,), np.uint8)
    out[..., :3] = (radiance * scale[..., None]).astype(np.uint8)
    out[..., 3] = np.where(top > 1e-32, exponent + 128, 0)
    return out


def run_length(values: np.ndarray) -> bytes:
    """One channel of one scanline: runs of three or more as (128 + n, value), the rest as literals."""
    out, k, n = bytearray(), 0, len(values)
    while k < n:
        run = 1
        while k + run < n and run < 127 and values[k + run] == values[k]:
            run += 1
        if run >= 3:
            out += bytes([128 + run, values[k]])
            k += run
            continue
        start = k
        while k < n and k - start < 128 and not (k + 2 < n and values[k] == values[k + 1] == values[k + 2]):
            k += 1
        out += bytes([k - start]) + bytes(values[start:k])
    return bytes(out)


def write_hdr(path, radiance, compressed=True):
    pixels = rgbe(radiance)
    h, w = pixels.shape[:2]
    body = bytearray()
    for row in pixels:
        if compressed:
            body += bytes([2, 2, w >> 8, w & 255])
            for channel in range(4):
                body += run_length(row[:, channel])
        else:
            body += row.tobytes()
    path.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode() + bytes(body))
    return path


def picture(h=6, w=40):
    """Runs and literals both: flat bands, a gradient, and a few bright texels."""
    rng = np.random.default_rng(3)
    radiance = np.ones((h, w, 3)) * [0.5, 0.25, 1.0]
    radiance[:, 10:25] = rng.uniform(0.01, 4.0, (h, 15, 3))
    radiance[2, 30] = (900.0, 20.0, 1.0)
    return radiance


@pytest.mark.parametrize("compressed", [True, False])
def test_reads_what_the_encoder_wrote(tmp_path, compressed):
    radiance = picture()
    decoded = read_radiance(write_hdr(tmp_path / "p.hdr", radiance, compressed))
    assert decoded.shape == radiance.shape and decoded.dtype == np.float32
    # RGBE keeps 8 bits of mantissa relative to each pixel's largest channel
    top = radiance.max(axis=2, keepdims=True)
    assert np.all(np.abs(decoded - radiance) <= top / 128)
    np.testing.assert_array_equal(decoded[0, 0], [0.5, 0.25, 1.0])  # exactly representable


def test_compressed_and_flat_scanlines_decode_to_the_same_picture(tmp_path):
    radiance = picture()
    a = read_radiance(write_hdr(tmp_path / "a.hdr", radiance, True))
    b = read_radiance(write_hdr(tmp_path / "b.hdr", radiance, False))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        (b"P6\n2 2\n255\n", "not a Radiance picture"),
        (b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n", "header never ends"),
        (b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n\x01\x01\x01\x80", "unsupported"),
        (b"#?RADIANCE\n\n+Y 1 +X 1\n\x01\x01\x01\x80", "orientation"),
        (b"#?RADIANCE\n\n-Y 2 +X 8\n\x02\x02\x00\x08\x88", "truncated or malformed"),
        (b"#?RADIANCE\n\n-Y 1 +X 4\n\x02\x02\x00\x04\x90\x01", "truncated or malformed"),  # run past the row
    ],
)
def test_broken_files_are_refused_with_their_name(tmp_path, content, needle):
    path = tmp_path / "bad.hdr"
    path.write_bytes(content)
    with pytest.raises(RadianceError, match=needle) as info:
        read_radiance(path)
    assert str(path) in str(info.value)


def test_tonemap_is_monotonic_bounded_and_exposure_brightens():
    radiance = np.array([[[0.0, 0.1, 1.0], [10.0, 1e4, np.inf]]], np.float32)
    display = tonemap(radiance)
    assert display.dtype == np.float32
    assert display[0, 0, 0] == 0.0 and np.all((display >= 0) & (display <= 1))
    assert np.all(np.diff(display.ravel()[:5]) > 0)  # 0 < 0.1 < 1 < 10 < 1e4
    assert display[0, 1, 2] == 1.0  # an infinite sun is white, not black
    assert np.isclose(display[0, 0, 2], (1 - math.exp(-1.0)) ** (1 / 2.2), atol=1e-6)
    assert np.all(tonemap(radiance[:, :1], exposure=1.0)[0, 0, 1:] > display[0, 0, 1:3])


def test_a_scene_with_an_hdr_panorama_shows_it_tonemapped(tmp_path):
    write_hdr(tmp_path / "sky.hdr", np.full((8, 16, 3), 2.0), True)
    path = tmp_path / "s.toml"
    path.write_text(
        '[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, -1]\n[environment]\nimage = "sky.hdr"\nexposure = -1\n'
    )
    scene = load_scene_file(path)
    image = paint(scene, scene.camera, 16, 8, PaintParams(iterations=2)).image
    np.testing.assert_allclose(image, (1 - math.exp(-1.0)) ** (1 / 2.2), atol=1e-6)  # 2 * 2^-1 = 1


def test_cli_environment_replaces_what_misses_see(tmp_path):
    write_hdr(tmp_path / "sky.hdr", np.full((8, 16, 3), 1.0), True)
    scene = tmp_path / "s.toml"
    scene.write_text("[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, -1]\n[environment]\ncolor = [0, 0, 0]\n")
    out = tmp_path / "o.png"
    argv = ["render", str(scene), "--out", str(out), "--width", "8", "--height", "4", "--environment"]
    assert main([*argv, str(tmp_path / "sky.hdr"), "--exposure", "0"]) == 0
    from PIL import Image

    assert np.all(np.asarray(Image.open(out)) == round((1 - math.exp(-1.0)) ** (1 / 2.2) * 255))
    assert main([*argv, str(tmp_path / "missing.hdr")]) == 2
