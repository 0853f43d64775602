"""Stills at print size: painted in bands that are crops of the one painting, streamed to a PNG with memory
that does not grow with the size; alpha where the plain image sees geometry; 16 bits a channel."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import av
import numpy as np
import pytest
from helpers.scenes import CAMERA
from PIL import Image

from rcp_server.bench.flicker import sight
from rcp_server.cli import main
from rcp_server.media import prints
from rcp_server.painting.loop import paint
from rcp_server.settings.params import PaintParams
from rcp_server.util import images

ROOT = Path(__file__).resolve().parents[2]
W, H = 96, 61
PARAMS = PaintParams(spp=2, noise=0.3, lambda_p=10.0, mapping="normal", iterations=4)


def decoded(path: Path) -> np.ndarray:
    """A PNG's pixels as FFmpeg's decoder reads them (16 bits kept): (h, w, channels)."""
    with av.open(str(path)) as container:
        frame = next(container.decode(video=0))
        name = frame.format.name
        wide = "64" in name or "48" in name
        alpha = "a" in name.removeprefix("rgb").removeprefix("bgr")
        kind = ("rgba64le" if alpha else "rgb48le") if wide else ("rgba" if alpha else "rgb24")
        return frame.to_ndarray(format=kind)


def write(tmp_path, scene, name, bits=8, alpha=False, params=PARAMS) -> Path:
    def paint_band(band, p):
        return paint(scene, CAMERA, W, H, p, region=band)

    out = tmp_path / name
    rows = prints.print_bands(scene, CAMERA, W, H, params, paint_band, bits=bits, alpha=alpha)
    prints.write_print(out, rows, W, H, bits, alpha)
    return out


def test_a_print_in_bands_is_the_painting_in_one_piece(busy_scene, tmp_path, monkeypatch):
    whole = paint(busy_scene, CAMERA, W, H, PARAMS).image
    monkeypatch.setattr(prints, "BAND_PIXELS", W * 7)  # bands of 7 rows, the last of 5
    assert [b.height for b in prints.bands(W, H)] == [7] * 8 + [5]
    out = write(tmp_path, busy_scene, "eight.png")
    np.testing.assert_array_equal(np.asarray(Image.open(out)), images.to_uint8(whole))
    np.testing.assert_array_equal(decoded(out), images.to_uint8(whole))
    sixteen = decoded(write(tmp_path, busy_scene, "sixteen.png", bits=16))
    assert sixteen.dtype == np.uint16
    np.testing.assert_array_equal(sixteen, np.round(np.clip(whole, 0, 1) * 65535).astype(np.uint16))
    assert len(np.unique(sixteen)) > 4 * len(np.unique(images.to_uint8(whole)))  # finer steps than 8 bits
    assert not list(tmp_path.glob(".*.part"))


def test_alpha_is_zero_exactly_where_the_plain_image_sees_no_geometry(busy_scene, tmp_path):
    params = replace(PARAMS, spp=1)
    out = decoded(write(tmp_path, busy_scene, "alpha.png", alpha=True, params=params))
    assert out.shape == (H, W, 4)
    hit = sight(busy_scene, CAMERA, W, H, 0.0).hit.reshape(H, W)  # the centre rays: the samples at 1 spp
    assert 0.2 < hit.mean() < 0.9
    np.testing.assert_array_equal(out[..., 3], np.where(hit, 255, 0))
    np.testing.assert_array_equal(out[..., :3], images.to_uint8(paint(busy_scene, CAMERA, W, H, params).image))
    wide = decoded(write(tmp_path, busy_scene, "alpha16.png", bits=16, alpha=True, params=params))
    np.testing.assert_array_equal(wide[..., 3], np.where(hit, 65535, 0))


def _peak_kb(width: int, height: int, out: Path) -> int:
    """Peak resident memory (KB) of ``rcp render sky`` at this size in a process of its own."""
    code = (
        "import resource, sys\nfrom rcp_server.cli import main\n"
        f"assert main(['-q', 'render', 'sky', '--width', '{width}', '--height', '{height}', '--iterations', '1', "
        f"'--bits', '16', '--out', {str(out)!r}]) == 0\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={"PYTHONPATH": str(ROOT)},
                         cwd=out.parent)  # fmt: skip
    assert run.returncode == 0, run.stderr
    return int(run.stdout.split()[-1])


def test_a_large_prints_memory_does_not_grow_with_its_size(tmp_path):
    base = _peak_kb(16, 16, tmp_path / "tiny.png")
    small = _peak_kb(4096, 256, tmp_path / "small.png")  # two bands
    large = _peak_kb(4096, 1024, tmp_path / "large.png")  # eight
    slope = (large - small) * 1024 / (4096 * (1024 - 256))  # bytes a pixel
    # a whole picture would cost 6 bytes a pixel as 16-bit rows, 12 as floats; the bands hold a constant
    assert slope < 1.0, (base, small, large)
    assert large - base < 300 * 1024, (base, large)
    with av.open(str(tmp_path / "large.png")) as container:
        assert next(container.decode(video=0)).to_ndarray(format="rgb48le").shape == (1024, 4096, 3)


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--width", "16385", "--height", "8", "--out", "x.png"], "a print is at most 16384x16384 pixels"),
        (["--alpha", "--out", "x.jpg"], "is written as a .png"),
        (["--bits", "16", "--frames", "2", "--out", "f/"], "--alpha and --bits make a still"),
        (["--bits", "12", "--out", "x.png"], "argument --bits: invalid choice"),
    ],
)
def test_prints_that_cannot_be_made_are_refused_in_one_line(args, said, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["render", "sky", "--width", "32", "--height", "16", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err, err
