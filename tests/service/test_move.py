"""The walk-through's ``move`` message: the server keeps the walker clear of the scene's surfaces (collide.py),
answering ``moved`` as the scene layer computes it; bad moves are one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from rcp_server.scene.walking import walk as walk_in

SCENE = "default"  # the village, standing on its ground at y = 0


def answer(walk, kind: str) -> dict:
    """The next message of ``kind`` (frames in between are read and dropped)."""
    while (reply := walk.next())["type"] != kind:
        assert reply["type"] in ("frame", "ready"), reply
        if reply["type"] == "frame":
            walk.ws.recv(30)
    return reply


def test_a_move_is_answered_with_the_scene_layers_collision(live_server, walk):
    walk.send(type="move", id=1, eye=[0, 1, 0], delta=[0, 0, 0])
    assert "say hello first" in answer(walk, "error")["message"]
    walk.send(type="hello", scene=SCENE, width=64, height=36)
    answer(walk, "ready")
    scene = live_server.app.state.service.scenes[SCENE]
    eye = list(scene.camera.eye)
    walk.send(type="move", id=2, eye=eye, delta=[0, 0, 0])
    measured = answer(walk, "moved")
    assert measured["id"] == 2 and measured["standing"] is True
    assert measured["height"] == pytest.approx(eye[1], abs=1e-4)  # the camera's eye above the ground
    assert measured["radius"] == pytest.approx(0.15 * eye[1], rel=1e-4)
    # a long stride towards the well: the server's answer is the scene layer's, to the float
    delta = [0.0, -0.2, -40.0]
    walk.send(type="move", id=3, eye=eye, delta=delta, height=measured["height"])
    moved = answer(walk, "moved")
    step = walk_in(scene, 0.0, eye, delta, measured["height"])
    assert moved["eye"] == step.eye.tolist() and moved["standing"] is True
    assert moved["eye"][1] == pytest.approx(eye[1], abs=1e-4)  # the legs keep it on the ground
    assert np.linalg.norm(np.subtract(moved["eye"], eye)) < 39  # something stopped it: the well, a house


def test_bad_moves_are_one_line_errors(live_server, walk):
    walk.send(type="hello", scene=SCENE, width=64, height=36)
    answer(walk, "ready")
    for bad in (
        {"eye": [0, 1], "delta": [0, 0, 0]},
        {"eye": [0, 1, 0], "delta": [0, 0, 1e12]},
        {"eye": [0, 1, 0], "delta": [0, 0, 0], "height": 0},
        {"delta": [0, 0, 0]},
    ):
        walk.send(type="move", id=1, **bad)
        error = answer(walk, "error")
        assert error["message"].startswith("bad message: ") and "\n" not in error["message"]
        assert (error["answers"], error["id"]) == ("move", 1)  # the client knows which move will not be answered
