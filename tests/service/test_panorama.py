"""Panoramas and stereo pairs through the service: REST renders and the walk-through take the camera's projection,
stereo and ipd (``width x height`` is one eye's image), paint exactly what the engine paints, and refuse a size or
a camera the projection cannot take in one line while the session goes on."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from helpers.wire import decode, post

from rcp_server.camera.wire import camera_of
from rcp_server.painting.loop import paint
from rcp_server.util import images

CAMERA = {"eye": [0.8, 1.7, 30.0], "look_at": [0.0, 2.0, 0.0]}


@pytest.mark.parametrize(
    ("camera", "eye_size", "size"),
    [
        ({"projection": "equirect"}, (64, 32), (64, 32)),
        ({"projection": "equirect", "stereo": "top-bottom", "ipd": 0.3}, (64, 32), (64, 64)),
        ({"stereo": "side-by-side", "ipd": 0.3}, (48, 30), (96, 30)),
    ],
)
def test_a_render_paints_the_projection_asked_for(live_server, camera, eye_size, size):
    body = {"scene": "default", "width": eye_size[0], "height": eye_size[1], "camera": {**CAMERA, **camera}}
    body["paint"] = {"iterations": 3}
    response = post(live_server, body)
    assert response.status_code == 200
    scene = live_server.app.state.service.scenes["default"]
    engine_camera = scene.camera.moved(eye=tuple(CAMERA["eye"]), look_at=tuple(CAMERA["look_at"]), **camera)
    expected = paint(scene, engine_camera, *size, replace(scene.paint, iterations=3)).image
    np.testing.assert_array_equal(decode(response.content), images.to_uint8(expected))


@pytest.mark.parametrize(
    ("camera", "says"),
    [
        ({"projection": "equirect"}, "width must be 2 x height"),
        ({"projection": "fisheye"}, "projection"),
        ({"stereo": "left-right"}, "stereo"),
        ({"stereo": "top-bottom", "ipd": -0.1}, "ipd"),
    ],
)
def test_a_camera_the_projection_cannot_take_is_refused_in_one_line(live_server, camera, says):
    body = {"scene": "default", "width": 64, "height": 40, "camera": {**CAMERA, **camera}}
    response = post(live_server, body)
    assert response.status_code == 422 and says in json.dumps(response.json()["detail"])


def test_the_wire_camera_carries_every_field_of_the_engines():
    from rcp_server.camera.wire import CameraSpec

    spec = CameraSpec(**CAMERA, projection="equirect", stereo="side-by-side", ipd=0.5)
    camera = camera_of(spec)
    assert (camera.projection, camera.stereo, camera.ipd) == ("equirect", "side-by-side", 0.5)


def test_the_walk_through_paints_a_panorama_and_refuses_a_size_it_cannot_take(walk):
    walk.send(type="hello", scene="default", width=64, height=36)
    walk.next()
    walk.until_final()
    # a panorama at this size: refused, the session goes on with its camera
    walk.send(type="camera", id=1, projection="equirect", **CAMERA)
    error = walk.next()
    assert error["type"] == "error" and "2 x height" in error["message"]
    assert (error["answers"], error["id"]) == ("camera", 1)  # the error names the message it refuses
    walk.send(type="view", width=64, height=32)
    walk.until_final()
    walk.send(type="camera", id=2, projection="equirect", stereo="top-bottom", ipd=0.3, **CAMERA)
    meta, image = walk.until_final()[-1]
    assert meta["camera_id"] == 2 and (meta["width"], meta["height"]) == (64, 64) and image.shape == (64, 64, 3)
    assert (meta["projection"], meta["stereo"]) == ("equirect", "top-bottom")  # the frame says how to show it
    # a view the panorama cannot take is refused too
    walk.send(type="view", width=64, height=36)
    refused = walk.next()
    assert "2 x height" in refused["message"] and (refused["answers"], refused["id"]) == ("view", None)
