"""The REST surface against its own OpenAPI schema, on a real server on loopback.

Schemathesis reads ``/openapi.json`` from a live server and sends every operation requests built from the schema
(valid and invalid bodies, boundary values, methods the schema does not list). No answer may be a 5xx or take
longer than ``TIMEOUT``, and every answer must be one the schema declares: its status code, content type and body.
The configuration is ``rcp bench fuzz``'s (``rcp_server/bench/fuzz.py``), with a fixed seed, derandomized and
learning nothing from the answers: every run sends the same requests, so a fresh clone and CI give the same
verdict. ``rcp bench fuzz`` is the longer, random run; what it once found is kept below as explicit cases.
"""

from __future__ import annotations

import time

import httpx
import pytest
import schemathesis
from helpers.servers import BackgroundServer

from rcp_server.bench.fuzz import AUTH, SERVER_SETTINGS, SIZES, TIMEOUT, open_schema

SEED = 20260101
EXAMPLES = 150
PARSE_ERROR = {"detail": "There was an error parsing the body"}


@pytest.fixture(scope="module")
def server():
    with BackgroundServer(**SERVER_SETTINGS) as server:
        yield server


@pytest.fixture(scope="module")
def api(server):
    return open_schema(server, SEED, EXAMPLES, deterministic=True)


schema = schemathesis.pytest.from_fixture("api")


@schema.parametrize()
def test_every_answer_is_declared_by_the_schema_and_none_is_a_server_error(case):
    case.call_and_validate(timeout=TIMEOUT)


# what the random fuzzing once found (500s), kept as explicit cases
LIMIT = 1e9
ONCE_FAILED = [
    # the spline carried the look-at past the coordinate limit between keyframes at it (CameraError)
    {
        "keyframes": [
            {"t": 0, "eye": [0, 0, 5], "look_at": [-LIMIT, 0, 0]},
            {"t": 1, "eye": [0, 0, 6], "look_at": [-LIMIT, LIMIT, 0]},
            {"t": 2, "eye": [0, 0, 6], "look_at": [-LIMIT, 0, -LIMIT]},
        ]
    },
    {
        "keyframes": [
            {"t": 0, "eye": [LIMIT, LIMIT, 0], "look_at": [0, LIMIT, 1]},
            {"t": 0.5, "eye": [-LIMIT, LIMIT, 1], "look_at": [LIMIT, LIMIT, 0]},
            {"t": 3, "eye": [0, -LIMIT, 0], "look_at": [LIMIT, LIMIT, LIMIT]},
        ]
    },
    # keyframes 1e-300 and 5e-324 seconds apart ("`dydx` must contain only finite values")
    {
        "keyframes": [
            {"t": 0, "eye": [0, 1, 5], "look_at": [0, 0, 0]},
            {"t": 1e-300, "eye": [1, 1, 5], "look_at": [0, 0, 0]},
        ]
    },
    {
        "loop": True,
        "keyframes": [
            {"t": 0, "eye": [0, 1, 5], "look_at": [0, 0, 0]},
            {"t": 5e-324, "eye": [1, 1, 5], "look_at": [0, 0, 0]},
        ],
    },
]


@pytest.mark.parametrize("path", ONCE_FAILED)
@pytest.mark.parametrize("route", ["/api/paths", "/api/videos"])
def test_what_the_fuzzing_once_found_is_answered_as_declared(server, route, path):
    scene = sorted(server.app.state.service.scenes)[0]
    body = {"scene": scene, "path": path, **({"width": 16, "height": 16} if route == "/api/videos" else {})}
    answer = httpx.post(server.url + route, json=body, headers=AUTH, timeout=TIMEOUT)
    assert answer.status_code in (200, 202, 422), answer.text
    if answer.status_code == 202:  # accepted: then it paints
        video = f"{server.url}/api/videos/{answer.json()['id']}"
        while (status := httpx.get(video, headers=AUTH, timeout=TIMEOUT).json())["state"] in ("queued", "running"):
            time.sleep(0.05)
        assert status["state"] == "done", status


def test_the_generated_requests_reach_the_painting(server):
    """The dictionaries do their job: a body the fuzzing sends (scene from the server, small size) paints."""
    body = {"scene": sorted(server.app.state.service.scenes)[0], "width": SIZES[1], "height": SIZES[2]}
    response = httpx.post(f"{server.url}/api/render", json=body, headers=AUTH, timeout=TIMEOUT)
    assert response.status_code == 200 and response.headers["content-type"] == "image/png"
    too_big = {**body, "width": 65, "height": 64}
    too_big = httpx.post(f"{server.url}/api/render", json=too_big, headers=AUTH, timeout=TIMEOUT)
    assert too_big.status_code == 422 and "pixels" in too_big.json()["detail"]


def test_a_body_that_is_not_json_text_gets_the_documented_400(server):
    response = httpx.post(
        f"{server.url}/api/render",
        content=b"\xc3\x12",
        headers={"content-type": "application/json", **AUTH},
        timeout=TIMEOUT,
    )
    assert response.status_code == 400 and response.json() == PARSE_ERROR
    assert (
        "400"
        in httpx.get(f"{server.url}/openapi.json", headers=AUTH).json()["paths"]["/api/render"]["post"]["responses"]
    )


def test_a_method_render_does_not_take_gets_405_with_post_allowed(server):
    get = httpx.get(f"{server.url}/api/render", timeout=TIMEOUT)
    options = httpx.options(f"{server.url}/api/render", timeout=TIMEOUT)
    assert (get.status_code, options.status_code) == (405, 405)
    assert get.headers["allow"] == options.headers["allow"] == "POST"
    assert httpx.get(f"{server.url}/api/nothing", timeout=TIMEOUT).status_code == 404  # not a client file lookup


def test_a_camera_whose_view_direction_would_overflow_is_refused(server):
    """Past about 1e154 the camera's norms would overflow to inf: coordinates are bounded at 1e9, in the schema
    (the OpenAPI schema and the client's both carry the bound)."""
    scene = sorted(server.app.state.service.scenes)[0]
    for camera in ({"eye": [1e308, 0, 0], "look_at": [-1e308, 0, 0]}, {"eye": [1e200, 0, 0], "look_at": [0, 0, 1]}):
        body = {"scene": scene, "width": 16, "height": 16, "camera": camera}
        response = httpx.post(f"{server.url}/api/render", json=body, headers=AUTH, timeout=TIMEOUT)
        detail = response.json()["detail"]
        assert response.status_code == 422 and "less than or equal to 1000000000" in detail[0]["msg"]
        assert detail[0]["loc"] == ["body", "camera", "eye", 0]
