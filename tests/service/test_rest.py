"""REST against a real server on loopback: health, the scene list, renders that are exactly the engine's
paintings, clear 4xx for bad requests, and an event loop that never waits for a painting."""

from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import httpx
import numpy as np
import pytest
from helpers.waits import wait_until
from helpers.wire import decode, post

from rcp_server.painting.loop import paint
from rcp_server.util import images


def test_health_and_scenes(live_server):
    health = httpx.get(f"{live_server.url}/api/health").json()
    assert health["status"] == "ok" and health["scenes"] >= 3
    scenes = {s["name"]: s for s in httpx.get(f"{live_server.url}/api/scenes").json()}
    assert {"default", "sea", "sky"} <= set(scenes)
    assert scenes["default"]["camera"]["fov"] > 0 and scenes["default"]["triangles"] > 0
    assert scenes["sea"]["animated"] and not scenes["default"]["animated"]


def test_render_is_exactly_the_engines_painting(live_server):
    body = {"scene": "default", "width": 96, "height": 54, "paint": {"iterations": 3, "lambda_p": 5.0}}
    response = post(live_server, body)
    assert response.status_code == 200 and response.headers["content-type"] == "image/png"
    scene = live_server.app.state.service.scenes["default"]
    expected = paint(scene, scene.camera, 96, 54, replace(scene.paint, **body["paint"])).image
    np.testing.assert_array_equal(decode(response.content), images.to_uint8(expected))


def test_render_takes_camera_time_and_jpeg(live_server):
    camera = {"eye": [0, 6, 5], "look_at": [-4.0, 4.0, -30.0], "fov": 40}
    body = {"scene": "sea", "width": 64, "height": 40, "camera": camera, "time": 1.5, "format": "jpeg"}
    response = post(live_server, body)
    assert response.status_code == 200 and response.headers["content-type"] == "image/jpeg"
    assert decode(response.content).shape == (40, 64, 3)
    still = decode(post(live_server, {**body, "time": 0.0}).content)
    assert np.abs(decode(response.content).astype(int) - still).mean() > 0.5  # the waves moved


@pytest.mark.parametrize(
    ("body", "status", "says"),
    [
        ({"scene": "atlantis"}, 404, "unknown scene 'atlantis'"),
        ({"scene": "../scenes/default"}, 422, "pattern"),
        ({}, 422, "scene"),
        ({"scene": "default", "width": 0}, 422, "width"),
        ({"scene": "default", "width": 4096, "height": 4096}, 422, "pixels"),
        ({"scene": "default", "paint": {"spp": 0}}, 422, "spp"),
        ({"scene": "default", "paint": {"mapping": "sepia"}}, 422, "mapping"),
        ({"scene": "default", "paint": {"brush": 3}}, 422, "brush"),
        ({"scene": "default", "camera": {"eye": [0, 0, 0], "look_at": [0, 0, 0]}}, 422, "eye"),
        ({"scene": "default", "camera": {"eye": [0, 0, 0], "look_at": [0, 1, 0]}}, 422, "up"),
        ({"scene": "default", "format": "gif"}, 422, "format"),
    ],
)
def test_bad_render_requests_get_a_clear_4xx(live_server, body, status, says):
    response = post(live_server, body)
    assert response.status_code == status
    assert says in json.dumps(response.json()["detail"])


def test_rendering_never_blocks_the_event_loop(live_server):
    big = {"scene": "default", "width": 640, "height": 360, "paint": {"spp": 8, "iterations": 6}}
    with ThreadPoolExecutor(3) as pool:
        renders = [pool.submit(post, live_server, big) for _ in range(2)]
        # the event loop answers while both paintings are in progress, as the answer itself says
        wait_until(lambda: httpx.get(f"{live_server.url}/api/health", timeout=10).json()["painting"] == 2)
        assert all(r.result().status_code == 200 for r in renders)


def test_openapi_documents_the_render_body(live_server):
    schema = httpx.get(f"{live_server.url}/openapi.json").json()
    assert "/api/render" in schema["paths"] and "RenderRequest" in schema["components"]["schemas"]
    assert httpx.get(f"{live_server.url}/docs").status_code == 200


def test_render_with_the_image_method_and_its_refusal_of_eye_moves(live_server):
    body = {"scene": "default", "width": 96, "height": 54, "paint": {"method": "image", "edge": "wrap"}}
    response = post(live_server, body)
    assert response.status_code == 200
    scene = live_server.app.state.service.scenes["default"]
    params = replace(scene.paint, **body["paint"])
    expected = paint(scene, scene.camera, 96, 54, params).image
    np.testing.assert_array_equal(decode(response.content), images.to_uint8(expected))
    refused = post(live_server, {**body, "paint": {"method": "image", "lambda_e": 0.1}})
    assert refused.status_code == 422 and "eye displacement" in refused.json()["detail"]


@pytest.mark.parametrize(
    ("path", "allow"),
    [("/api/scenes", "GET, POST"), ("/api/videos/some-id", "GET, DELETE"), ("/api/scenes/default", "GET, DELETE")],
)
def test_a_method_a_path_lacks_gets_405_naming_every_method_of_its_routes(live_server, path, allow):
    """One mechanism sets Allow (app._http_error), for paths whose methods are several routes."""
    answer = httpx.put(live_server.url + path, timeout=30)
    assert answer.status_code == 405 and answer.headers["allow"] == allow and "detail" in answer.json()
