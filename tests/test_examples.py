"""The files of ``examples/`` work as the documentation says: each is rendered through the real ``rcp`` command
at a small size and checked against the public API's painting of the same thing, and for what it claims to do."""

import json
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image

from rcp_server import PaintParams, load_scene, paint
from rcp_server.cli import main
from rcp_server.media.camerapath import load_path
from rcp_server.util.images import save

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
W, H = 64, 36
SMALL = ["--width", str(W), "--height", str(H)]


def _pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"))


def _as_saved(image: np.ndarray, tmp_path: Path, name: str) -> np.ndarray:
    """The API's image as ``rcp render`` writes it (the same encoder), read back."""
    save(tmp_path / name, image)
    return _pixels(tmp_path / name)


def _shows(scene, params: PaintParams, names: tuple[str, ...]) -> np.ndarray:
    """Where the plain render shows one of the objects ``names``: (H, W) bool."""
    probe = PaintParams(iterations=1, objects={name: {"lambda_p": 0.0} for name in names})
    state = paint(scene, scene.camera, W, H, probe).state
    known = scene.geometry()[0].object_names
    return np.isin(state.object, [known.index(name) for name in names]).reshape(H, W)


def test_the_camera_path_walks_the_default_scene_from_its_camera(tmp_path):
    frames = tmp_path / "frames"
    assert main(["-q", "render", "default", "--path", str(EXAMPLES / "walk.json"), "--fps", "1", *SMALL,
                 "--out", f"{frames}/"]) == 0  # fmt: skip
    written = sorted(frames.glob("frame_*.png"))
    last = json.loads((EXAMPLES / "walk.json").read_text())["keyframes"][-1]["t"]
    assert len(written) == int(last) + 1  # at 1 frame a second, both ends included
    still = tmp_path / "still.png"
    assert main(["-q", "render", "default", *SMALL, "--out", str(still)]) == 0
    # the path starts where the scene's camera stands, so its first frame is the scene's own painting
    np.testing.assert_array_equal(_pixels(written[0]), _pixels(still))
    images = [_pixels(path).astype(np.int16) for path in written]
    for before, after in zip(images, images[1:], strict=False):
        assert (np.abs(after - before).max(axis=2) > 8).mean() > 0.2  # every frame has moved on


def test_the_paint_file_paints_the_houses_by_their_normals_and_keeps_the_trees(tmp_path):
    out = tmp_path / "painted.png"
    source = EXAMPLES / "paint.toml"
    assert main(["-q", "render", "default", "--paint", str(source), *SMALL, "--out", str(out)]) == 0
    scene = load_scene("default")
    params = scene.painting(tomllib.loads(source.read_text()))
    expected = paint(scene, scene.camera, W, H, params).image
    np.testing.assert_array_equal(_pixels(out), _as_saved(expected, tmp_path, "api.png"))

    plain = paint(scene, scene.camera, W, H, replace(params, iterations=1)).image
    trees = _shows(scene, params, ("crowns", "trunks"))
    assert trees.mean() > 0.01
    np.testing.assert_array_equal(expected[trees], plain[trees])  # lambda_p 0: exactly as rendered
    own = paint(scene, scene.camera, W, H, scene.paint).image
    assert (np.abs(expected - own).max(axis=2) > 2 / 255).mean() > 0.2  # the file changes the painting


def test_the_scene_file_keeps_its_figure_sharp_among_smudged_blocks(tmp_path):
    out = tmp_path / "still.png"
    source = EXAMPLES / "scene.toml"
    assert main(["-q", "render", str(source), *SMALL, "--out", str(out)]) == 0
    scene = load_scene(str(source))
    painted = paint(scene, scene.camera, W, H, scene.paint).image
    np.testing.assert_array_equal(_pixels(out), _as_saved(painted, tmp_path, "api.png"))

    plain = paint(scene, scene.camera, W, H, replace(scene.paint, iterations=1)).image
    figure, blocks = _shows(scene, scene.paint, ("figure", "head")), _shows(scene, scene.paint, ("blocks",))
    assert figure.mean() > 0.02 and blocks.mean() > 0.05
    np.testing.assert_array_equal(painted[figure], plain[figure])
    moved = np.abs(painted - plain).max(axis=2) > 2 / 255
    assert moved[blocks].mean() > 0.2


def test_the_film_keys_its_painting_from_plain_to_smudged_to_fractured(tmp_path):
    frames = tmp_path / "frames"
    source = EXAMPLES / "film.json"
    assert main(["-q", "render", "default", "--path", str(source), "--fps", "1", *SMALL, "--out", f"{frames}/"]) == 0
    written = [_pixels(path) for path in sorted(frames.glob("frame_*.png"))]
    assert len(written) == 10
    scene = load_scene("default")
    path = load_path(source, scene.camera, fps=1).with_painting(scene.paint, scene.check_names)
    cameras, _ = path.at(np.arange(10.0))

    def api(t: int, params: PaintParams) -> np.ndarray:
        return paint(scene, cameras[t], W, H, params, time=float(t)).image

    smudge = scene.painting({"style": "smudge", "objects": {"crowns": {"lambda_p": 0}}})
    # lambda_p 0 at first: the plain render; at 3 s the smudge its key gives, and half-way (a straight line
    # between two keys) from the smudge's surface noise and grain to those the fractured style keys at 6 s
    plain = api(0, replace(smudge, iterations=1))
    np.testing.assert_array_equal(written[0], _as_saved(plain, tmp_path, "0.png"))
    keyed = replace(smudge, lambda_p=24.0, noise=0.3, surface_noise=0.3, grain=(0.05 + 0.8) / 2)
    np.testing.assert_array_equal(written[3], _as_saved(api(3, keyed), tmp_path, "3.png"))
    # at 5 s, half-way through the 2 s fade into the fractured style: half of each painting
    (colour, w0), (normal, w1) = next(f for f in path.frames() if f.index == 5).looks
    assert (colour.mapping, normal.mapping, w0, w1) == ("color", "normal", 0.5, 0.5)
    assert colour.lambda_p == normal.lambda_p and 14.0 < colour.lambda_p < 24.0
    blend = 0.5 * api(5, colour) + 0.5 * api(5, normal)
    np.testing.assert_array_equal(written[5], _as_saved(blend, tmp_path, "5.png"))
