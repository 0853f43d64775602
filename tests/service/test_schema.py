"""The REST surface against its own OpenAPI schema, on a real server on loopback.

Schemathesis reads ``/openapi.json`` from a live server and sends every operation requests built from the schema
(valid and invalid bodies, boundary values, methods the schema does not list). No answer may be a 5xx or take
longer than ``TIMEOUT``, and every answer must be one the schema declares: its status code, content type and body.
Two things the schema cannot say are told to the generator: scene names are data (``dictionaries`` draws most
bodies' ``scene`` from the server's own scenes), and ``width * height`` must stay under ``max_pixels``, so
small sizes are drawn often and a schema-valid body may still get the documented 422. The server's limit is
64x64 pixels, so every painting that passes is cheap. The seed is fixed: a failure reproduces.
"""

from __future__ import annotations

import httpx
import pytest
import schemathesis

from rcp_server.bench.harness import BackgroundServer

MAX_PIXELS = 64 * 64
TOKEN = "schema-token"  # schemathesis brings it, and checks that requests without it or with another get 401
AUTH = {"authorization": f"Bearer {TOKEN}"}
TIMEOUT = 30  # seconds; the largest painting the limits allow (MAX_WORK rays) takes about 4
MAX_WORK = 1 << 24  # 64x64 pixels x 64 iterations x 64 spp
SIZES = [1, 7, 16, 64]  # widths and heights whose products stay within MAX_PIXELS
PARSE_ERROR = {"detail": "There was an error parsing the body"}


@pytest.fixture(scope="module")
def server():
    # a video the fuzzing sends is at most a few small paintings' work
    settings = {"max_pixels": MAX_PIXELS, "max_work": MAX_WORK, "max_video_work": 4 * MAX_WORK, "token": TOKEN}
    with BackgroundServer(**settings) as server:
        yield server


@pytest.fixture(scope="module")
def api(server):
    config = schemathesis.Config.from_dict(
        {
            "seed": 20260101,
            "generation": {"max-examples": 150, "database": "none"},  # no example database left in the tree
            "request-timeout": TIMEOUT,
            "auth": {"openapi": {"HTTPBearer": {"bearer": TOKEN}, "APIKeyQuery": {"api_key": TOKEN}}},
            "dictionaries": {
                "scenes": {"values": sorted(server.app.state.service.scenes)},
                "sizes": {"values": SIZES},
            },
            "parameters": {
                # most bodies name a scene that exists (the rest get 404) and half of the sizes are small
                "body.scene": {"dictionary": "scenes", "probability": 0.9},
                "body.width": {"dictionary": "sizes", "probability": 0.5},
                "body.height": {"dictionary": "sizes", "probability": 0.5},
            },
            "checks": {
                # a schema-valid body may name an unknown scene (404) or, through width * height, an eye on its
                # look_at point or an up along the view, ask for a painting the server cannot make (422)
                # (and a video's path of many keyframes may be longer than RCP_MAX_BODY_BYTES: 413)
                "positive_data_acceptance": {"expected-statuses": ["2xx", 404, 413, 422]},
                # a body past RCP_MAX_BODY_BYTES is turned away before it is read (a video path with more than
                # the keyframes allowed cannot be written shorter): 413 refuses it as surely as 422
                "negative_data_rejection": {"expected-statuses": [400, 401, 403, 404, 405, 406, 409, 413, 415, 422]},
            },
        }
    )
    schema = schemathesis.openapi.from_url(f"{server.url}/openapi.json", config=config, timeout=TIMEOUT, headers=AUTH)

    return schema


schema = schemathesis.pytest.from_fixture("api")


@schema.parametrize()
def test_every_answer_is_declared_by_the_schema_and_none_is_a_server_error(case):
    case.call_and_validate(timeout=TIMEOUT)


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
    """Past about 1e154 the camera's norms would overflow to inf: coordinates are bounded at 1e9."""
    scene = sorted(server.app.state.service.scenes)[0]
    for camera in ({"eye": [1e308, 0, 0], "look_at": [-1e308, 0, 0]}, {"eye": [1e200, 0, 0], "look_at": [0, 0, 1]}):
        body = {"scene": scene, "width": 16, "height": 16, "camera": camera}
        response = httpx.post(f"{server.url}/api/render", json=body, headers=AUTH, timeout=TIMEOUT)
        assert response.status_code == 422 and "1e+09" in response.json()["detail"]
