"""The ``rcp`` command line: stills, iterations, sequences, scene listing, and one-line errors."""

import re
import subprocess
import sys

import numpy as np
import pytest
from helpers.scenes import SPINNING_BOX
from PIL import Image

from rcp_server.camera.camera import Camera
from rcp_server.cli import camera_path, main
from rcp_server.scene.scenefile import scene_names

SMALL = ["--width", "48", "--height", "32"]


def _scene_file(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(SPINNING_BOX)
    return path


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("rcp: error: ")
    return err[0]


def test_render_writes_the_painting(tmp_path):
    out = tmp_path / "still.png"
    assert main(["render", str(_scene_file(tmp_path)), "--out", str(out), *SMALL]) == 0
    image = np.asarray(Image.open(out))
    assert image.shape == (32, 48, 3)
    assert image.std() > 5  # a box against the sky, not a flat fill


@pytest.mark.parametrize(
    ("options", "shape"),
    [
        (["--projection", "equirect", "--width", "64", "--height", "32"], (32, 64, 3)),
        (["--projection", "equirect", "--stereo", "top-bottom", "--width", "64", "--height", "32"], (64, 64, 3)),
        (["--stereo", "side-by-side", "--ipd", "0.2", *SMALL], (32, 96, 3)),
    ],
)
def test_render_paints_panoramas_and_stereo_pairs_of_one_eyes_size(tmp_path, options, shape):
    out = tmp_path / "pano.png"
    assert main(["render", str(_scene_file(tmp_path)), "--out", str(out), "--iterations", "2", *options]) == 0
    assert np.asarray(Image.open(out)).shape == shape


def test_save_iterations_writes_every_iteration_and_the_last_is_the_output(tmp_path):
    out = tmp_path / "still.png"
    argv = [
        "render",
        str(_scene_file(tmp_path)),
        "--out",
        str(out),
        *SMALL,
        "--iterations",
        "4",
        "--save-iterations",
        str(tmp_path / "its"),
    ]
    assert main(argv) == 0
    files = sorted((tmp_path / "its").glob("iteration_*.png"))
    assert [f.name for f in files] == [f"iteration_{k}.png" for k in range(1, 5)]
    assert np.array_equal(np.asarray(Image.open(files[-1])), np.asarray(Image.open(out)))


def test_frames_over_time_write_a_numbered_sequence_that_moves(tmp_path):
    out = tmp_path / "seq.png"
    argv = [
        "-q",
        "render",
        str(_scene_file(tmp_path)),
        "--out",
        str(out),
        *SMALL,
        "--frames",
        "3",
        "--fps",
        "2",
        "--temporal",
        "2",
    ]
    assert main(argv) == 0
    frames = [np.asarray(Image.open(tmp_path / f"seq_{k:04d}.png")) for k in range(3)]
    assert not np.array_equal(frames[0], frames[1])  # the box spins 45 degrees a frame


def test_camera_path_orbits_around_the_target_and_walks_forward():
    camera = Camera((0, 1, 4), (0, 1, 0))
    half = camera_path(camera, 1.0, 90.0, 0.0)
    assert np.allclose(half.look_at, camera.look_at)
    assert np.allclose(half.eye, (4, 1, 0), atol=1e-9)  # a quarter turn about +y, counter-clockwise
    walked = camera_path(camera, 0.5, 0.0, 2.0)
    assert np.allclose(walked.eye, (0, 1, 3)) and np.allclose(walked.look_at, (0, 1, -1))


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["render", "nowhere-scene", "--out", "x.png"], "unknown scene 'nowhere-scene'"),
        (["render", "{scene}", "--out", "x.gif"], "unknown image type"),
        (
            ["render", "{scene}", "--out", "x.png", "--mapping", "swirly"],
            "valid mappings: color, cubist, depth, normal",
        ),
        (["render", "{scene}", "--out", "x.png", "--width", "0"], "positive integer"),
        (["render", "{scene}", "--out", "x.png", "--lambda-p", "nan"], "finite"),
        (
            ["render", "{scene}", "--out", "x.png", "--eye", "0", "0.5", "0", "--look-at", "0", "0.5", "0"],
            "eye and look_at coincide",
        ),
        (
            [
                "render",
                "{scene}",
                "--out",
                "x.png",
                "--up",
                "0",
                "0",
                "1",
                "--eye",
                "0",
                "0",
                "5",
                "--look-at",
                "0",
                "0",
                "0",
            ],
            "up is parallel",
        ),
        (["render", "{scene}", "--out", "x.png", "--fov", "180"], "fov"),
        (["render", "{scene}", "--out", "x.png", "--projection", "equirect", *SMALL], "width must be 2 x height"),
        (["render", "{scene}", "--out", "x.png", "--projection", "fisheye"], "invalid choice"),
        (["render", "{scene}", "--out", "x.png", "--stereo", "top-bottom", "--ipd", "-1"], "ipd"),
        (["render", "{scene}"], "--out"),
        (["render", "{scene}", "--out", "x.png", "--width", "200000", "--height", "200000"], "at most 16384x16384"),
        (["paint"], "invalid choice"),
    ],
)
def test_bad_arguments_give_one_line_and_exit_code_2(tmp_path, capsys, argv, needle):
    scene = str(_scene_file(tmp_path))
    argv = [a.replace("{scene}", scene) for a in argv]
    assert main(argv) == 2
    assert needle in _one_error_line(capsys)


def test_unwritable_output_is_a_one_line_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["render", str(_scene_file(tmp_path)), "--out", str(blocker / "x.png"), *SMALL]) == 2
    _one_error_line(capsys)


def test_console_script_exit_code_and_no_traceback(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "rcp_server.cli",
            "render",
            str(tmp_path / "broken.toml"),
            "--out",
            str(tmp_path / "x.png"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_every_shipped_scene_loads_and_paints(tmp_path, capsys):
    names = scene_names()
    assert {"default", "sky", "sea"} <= set(names)
    assert main(["scenes"]) == 0
    listing = capsys.readouterr().out
    assert "BROKEN" not in listing
    assert all(name in listing for name in names)
    for name in names:
        out = tmp_path / f"{name}.png"
        assert main(["render", name, "--out", str(out), "--width", "32", "--height", "18", "--time", "0.5"]) == 0
        assert np.asarray(Image.open(out)).std() > 1, name


def test_bench_speed_prints_the_stage_split_and_the_ratios_to_embreex_and_to_embree_packets(capsys):
    assert main(["bench", "speed", "--width", "64", "--height", "36", "--iterations", "2", "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    for needle in (
        "triangles",
        "nanoseconds a pixel an iteration",
        "cameras",
        "ray (screen cells or Embree",
        "shading",
        "carrying pixels",
        "embreex alone",
        "ratio iteration / embreex",
        "packets alone",
        "ratio iteration / packets",
        "a whole painting (2 iterations) / one embreex pass",
        "the scene's own painting",
    ):
        assert needle in out, needle
    stages = re.findall(r"^  (cameras|ray|shading|carrying).*?(\d+\.\d) ns", out, re.M)
    assert len(stages) == 4 and all(float(ns) >= 0 for _, ns in stages)


def test_compile_warms_every_kernel_the_server_warms_and_says_so(capsys):
    """``rcp compile`` (the container image's build step) runs the server's warm-up: afterwards every engine
    kernel a painting calls has a compiled version in this process."""
    from rcp_server.engine.kernels import screencells, visibility
    from rcp_server.painting import warmup

    assert main(["compile"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"rcp: the kernels of {len(scene_names())} scenes are compiled (in ") and out.count("\n") == 1
    called = [kernel for kernel in warmup.kernels() if kernel.overloads]
    assert len(called) >= 2  # at least the iteration and the first cast (the others load inside them)
    # the screen cells too, which only large paintings build
    assert screencells._fill in called and visibility.answer_listed in called
