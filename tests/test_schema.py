"""The REST surface against its own OpenAPI schema, on a real server on loopback.

Schemathesis reads ``/openapi.json`` from a live server and sends every operation requests built from the schema
(valid and invalid bodies, boundary values, methods the schema does not list). No answer may be a 5xx or take
longer than ``TIMEOUT``, and every answer must be one the schema declares: its status code, content type and body.
Two things the schema cannot say are told to the generator: scene names are data (``dictionaries`` draws most
bodies' ``scene`` from the server's own scenes), and ``width * height`` must stay under ``max_pixels``, so
small sizes are drawn often and a schema-valid body may still get the documented 422. The server's limit is
64x64 pixels, so every painting that passes is cheap. The seed is fixed: a failure reproduces.

Known deviations, each dropped from the fuzzing by one precise filter and pinned by a strict xfail test below
that fails (XPASS) once the server is fixed, so the filter and the xfail can go together.
"""

from __future__ import annotations

import httpx
import pytest
import schemathesis

from rcp_server.service.background import BackgroundServer

MAX_PIXELS = 64 * 64
TIMEOUT = 30  # seconds; the largest painting the limit allows (64x64, 64 iterations, 64 spp) takes about 4
SIZES = [1, 7, 16, 64]  # widths and heights whose products stay within MAX_PIXELS
PARSE_ERROR = {"detail": "There was an error parsing the body"}


@pytest.fixture(scope="module")
def server():
    with BackgroundServer(max_pixels=MAX_PIXELS) as server:
        yield server


def _known_deviation(failure, case, response) -> bool:
    """Failures the xfail tests below pin: FastAPI's undocumented 400 for a body that is not UTF-8, and the
    client's static files at ``/`` answering methods ``/api/render`` does not take."""
    if type(failure).__name__ == "UndefinedStatusCode":
        return response.status_code == 400 and response.json() == PARSE_ERROR
    if type(failure).__name__ in ("UnsupportedMethodResponse", "AllowHeaderMismatch"):
        return case.path == "/api/render" and case.method != "POST"
    return False


@pytest.fixture(scope="module")
def api(server):
    config = schemathesis.Config.from_dict(
        {
            "seed": 20260101,
            "generation": {"max-examples": 150, "database": "none"},  # no example database left in the tree
            "request-timeout": TIMEOUT,
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
                "positive_data_acceptance": {"expected-statuses": ["2xx", 404, 422]},
            },
        }
    )
    schema = schemathesis.openapi.from_url(f"{server.url}/openapi.json", config=config, timeout=TIMEOUT)

    @schema.hook
    def filter_failure(context, failure, case, response) -> bool:
        return not _known_deviation(failure, case, response)

    return schema


schema = schemathesis.pytest.from_fixture("api")


@schema.parametrize()
def test_every_answer_is_declared_by_the_schema_and_none_is_a_server_error(case):
    case.call_and_validate(timeout=TIMEOUT)


def test_the_generated_requests_reach_the_painting(server):
    """The dictionaries do their job: a body the fuzzing sends (scene from the server, small size) paints."""
    body = {"scene": sorted(server.app.state.service.scenes)[0], "width": SIZES[1], "height": SIZES[2]}
    response = httpx.post(f"{server.url}/api/render", json=body, timeout=TIMEOUT)
    assert response.status_code == 200 and response.headers["content-type"] == "image/png"
    too_big = httpx.post(f"{server.url}/api/render", json={**body, "width": 65, "height": 64}, timeout=TIMEOUT)
    assert too_big.status_code == 422 and "pixels" in too_big.json()["detail"]


@pytest.mark.xfail(strict=True, reason="FastAPI answers a body that is not UTF-8 with 400, which the schema omits")
def test_a_body_that_is_not_utf8_gets_a_documented_status(server):
    response = httpx.post(
        f"{server.url}/api/render", content=b"\xc3\x12", headers={"content-type": "application/json"}, timeout=TIMEOUT
    )
    assert response.json() == PARSE_ERROR  # the deviation the fuzzing filter drops, exactly
    assert response.status_code in (404, 422)


@pytest.mark.xfail(strict=True, reason="the client's static files at / answer GET and OPTIONS on /api/render")
def test_a_method_render_does_not_take_gets_405_with_post_allowed(server):
    get = httpx.get(f"{server.url}/api/render", timeout=TIMEOUT)
    options = httpx.options(f"{server.url}/api/render", timeout=TIMEOUT)
    assert (get.status_code, options.status_code) == (405, 405)
    assert get.headers["allow"] == options.headers["allow"] == "POST"


@pytest.mark.xfail(strict=True, reason="eye - look_at overflows float64: the painting is all black, answered 200")
def test_a_camera_whose_view_direction_overflows_is_refused(server):
    """Coordinates are unbounded in the schema; past about 1e154 the camera's norms overflow to inf and NaN."""
    camera = {"eye": [1e308, 0, 0], "look_at": [-1e308, 0, 0]}
    body = {"scene": sorted(server.app.state.service.scenes)[0], "width": 16, "height": 16, "camera": camera}
    response = httpx.post(f"{server.url}/api/render", json=body, timeout=TIMEOUT)
    assert response.status_code == 422
