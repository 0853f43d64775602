"""``examples/walk.json``, the README's camera path, ships with the repository and renders as it says."""

from __future__ import annotations

import json
from pathlib import Path

import av
import numpy as np

from rcp_server.cli import main
from rcp_server.media.camerapath import load_path
from rcp_server.scene.scenefile import load_scene
from rcp_server.scene.walking import walk

WALK = Path(__file__).resolve().parents[2] / "examples" / "walk.json"


def test_the_example_path_renders_the_default_scene_to_an_mp4(tmp_path):
    out = tmp_path / "walk.mp4"
    assert (
        main(
            [
                "render",
                "default",
                "--path",
                str(WALK),
                "--out",
                str(out),
                "--fps",
                "2",
                "--width",
                "64",
                "--height",
                "36",
                "--iterations",
                "2",
            ]
        )
        == 0
    )
    with av.open(str(out)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    last = json.loads(WALK.read_text())["keyframes"][-1]["t"]
    assert len(frames) == int(last * 2) + 1 and frames[0].shape == (36, 64, 3)
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 5  # it goes somewhere


def test_the_example_walk_keeps_clear_of_the_village():
    """A walker at every frame's eye keeps its radius from every surface (the collision leaves a still walker
    where it is) and stands on the ground: the path walks down the street, through no wall."""
    scene = load_scene("default")
    path = load_path(WALK, scene.camera, fps=6)
    for frame in path.frames():
        eye = frame.camera.eye
        step = walk(scene, 0.0, eye, (0, 0, 0))
        assert step.standing and np.allclose(step.eye, eye, atol=1e-5), frame
        assert 1.6 < step.body.height < 1.9  # eye high, on the ground
