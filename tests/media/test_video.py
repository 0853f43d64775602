"""``rcp render --path``: a camera path painted into an MP4 (decoded back with PyAV) or numbered PNGs, frame
for frame the engine's paintings; and its bad input, refused in one line before anything is painted."""

from __future__ import annotations

import json
from dataclasses import replace

import av
import numpy as np
import pytest
from helpers.scenes import SPINNING_BOX
from PIL import Image

from rcp_server.cli import main
from rcp_server.media.camerapath import load_path
from rcp_server.media.video import Mp4Writer
from rcp_server.painting.loop import paint
from rcp_server.scene.scenefile import load_scene
from rcp_server.util import images

SIZE = ["--width", "48", "--height", "32"]
# the spinning box, painted with a small smudge, beside a sphere
SCENE = (
    SPINNING_BOX
    + """
[[objects]]
primitive = { type = "sphere", radius = 0.4 }
color = [0.1, 0.8, 0.3]
translate = [1.2, 0.4, 0]
[paint]
lambda_p = 4
"""
)
PATH = {
    "fps": 8,
    "keyframes": [
        {"t": 0, "eye": [0, 1, 4], "look_at": [0, 0.5, 0]},
        {"t": 0.5, "eye": [2.5, 1.2, 3], "look_at": [0, 0.5, 0], "fov": 50},
        {"t": 1, "eye": [3.5, 1.5, 0.5], "look_at": [0, 0.4, 0]},
    ],
}


@pytest.fixture
def files(tmp_path):
    scene, path = tmp_path / "tiny.toml", tmp_path / "walk.json"
    scene.write_text(SCENE)
    path.write_text(json.dumps(PATH))
    return scene, path


def paintings(scene_file, path_file, width=48, height=32, temporal=None, **settings):
    """The engine's paintings of the path, painted here one by one (what every frame must show)."""
    scene = load_scene(str(scene_file))
    params = replace(scene.paint, **settings)
    out, previous = [], None
    for frame in load_path(path_file, scene.camera).frames():
        frame_params = replace(params, iterations=temporal) if temporal and previous is not None else params
        result = paint(scene, frame.camera, width, height, frame_params, time=frame.scene_time, previous=previous)
        previous = result.state if temporal else None
        out.append(images.to_uint8(result.image))
    return out


def decoded(video_file) -> list[np.ndarray]:
    with av.open(str(video_file)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264"
        assert stream.codec_context.pix_fmt == "yuv420p"
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(stream)]


def subsampled(image: np.ndarray) -> np.ndarray:
    """``image`` (h, w, 3) uint8 through yuv420p and back, as a player shows it: what H.264 must keep."""
    frame = av.VideoFrame.from_ndarray(image, format="rgb24").reformat(format="yuv420p")
    return frame.reformat(format="rgb24").to_ndarray()


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return 10 * np.log10(255.0**2 / mse)


def test_a_path_becomes_an_mp4_of_its_paintings(files, tmp_path):
    scene, path = files
    out = tmp_path / "out" / "walk.mp4"
    assert main(["-q", "render", str(scene), "--path", str(path), "--out", str(out), *SIZE]) == 0
    frames = decoded(out)
    expected = paintings(scene, path)
    assert len(frames) == len(expected) == 9  # 1 s at 8 fps, both ends
    assert all(f.shape == (32, 48, 3) for f in frames)
    for frame, painting in zip(frames, expected, strict=True):
        assert psnr(frame, subsampled(painting)) > 35  # the codec's loss beyond yuv420p's halved color...
        assert psnr(frame, painting) > 23  # ...which costs a painting's fine colored strokes more
    for k in range(1, 9):  # each frame is its own: much closer to its painting than to its neighbour's
        assert psnr(frames[k], subsampled(expected[k])) > psnr(frames[k], subsampled(expected[k - 1])) + 10
    assert list(out.parent.iterdir()) == [out]  # nothing left beside it


def test_a_folder_gets_numbered_pngs_equal_to_the_paintings_temporal_too(files, tmp_path):
    scene, path = files
    out = tmp_path / "frames"
    argv = ["-q", "render", str(scene), "--path", str(path), "--out", f"{out}/", *SIZE, "--spp", "2", "--temporal", "2"]
    assert main(argv) == 0
    expected = paintings(scene, path, temporal=2, spp=2)
    written = sorted(out.iterdir())
    assert [p.name for p in written] == [f"frame_{k:04d}.png" for k in range(9)]
    for file, painting in zip(written, expected, strict=True):
        np.testing.assert_array_equal(np.asarray(Image.open(file)), painting)
    # temporal mode is not per-frame mode: later frames continue from the earlier ones
    per_frame = paintings(scene, path, spp=2)
    assert not np.array_equal(per_frame[5], expected[5])


def test_fps_and_size_options_apply_to_a_path(files, tmp_path):
    scene, path = files
    out = tmp_path / "half"
    assert main(["-q", "render", str(scene), "--path", str(path), "--out", str(out), "--fps", "4"]) == 0
    written = sorted(out.iterdir())
    assert len(written) == 5  # the path's 1 s at 4 fps
    assert Image.open(written[0]).size == (640, 360)


def test_a_failed_video_leaves_nothing_behind(tmp_path):
    out = tmp_path / "v.mp4"
    writer = Mp4Writer(out, 16, 16, 24.0)
    for _ in range(3):
        writer.write(np.full((16, 16, 3), 0.5, np.float32))
    writer.abort()
    assert list(tmp_path.iterdir()) == []
    out.write_bytes(b"a video that was here before")
    writer = Mp4Writer(out, 16, 16, 24.0)
    writer.write(np.zeros((16, 16, 3), np.float32))
    writer.abort()
    assert out.read_bytes() == b"a video that was here before"


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--out", "v.mp4", "--width", "47", "--height", "32"], "even width and height, got 47x32"),
        (["--out", "v.mp4", "--frames", "3"], "leave out --frames"),
        (["--out", "v.gif"], "unknown image type"),
        (["--out", "v.mp4", "--fps", "0"], "--fps must be positive, got 0"),
        (["--out", "v.mp4", "--fps", "1000"], "fps: Input should be less than or equal to 240"),
    ],
)
def test_bad_sequences_are_refused_in_one_line(files, tmp_path, capsys, argv, says, monkeypatch):
    scene, path = files
    monkeypatch.chdir(tmp_path)
    assert main(["render", str(scene), "--path", str(path), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rcp: error: ") and says in err[0], err
    assert not (tmp_path / "v.mp4").exists()


def test_a_broken_path_file_is_refused_naming_the_file_and_field(files, tmp_path, capsys):
    scene, path = files
    broken = dict(PATH, keyframes=[PATH["keyframes"][1], PATH["keyframes"][0]])
    path.write_text(json.dumps(broken))
    assert main(["render", str(scene), "--path", str(path), "--out", str(tmp_path / "v.mp4")]) == 2
    err = capsys.readouterr().err.strip()
    said = "keyframes.1.t: must be greater than the previous keyframe's t, by 0.001 s at least (0 after 0.5)"
    assert err == f"rcp: error: {path}: {said}"
