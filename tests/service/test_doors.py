"""The same limits on every door: one request over the pixel or the work limit is refused alike, in the same one
line, by a REST render, the walk's ``hello``, every later camera, view and paint message of a walk, and a video
job; a stereo camera counts both eyes and all samples (a real server on loopback)."""

from __future__ import annotations

import httpx
import pytest
from helpers.scenes import SPINNING_BOX
from helpers.servers import BackgroundServer
from helpers.wire import Walk

SIDE = 540  # the limit is one eye of SIDE x SIDE: a stereo pair of it is twice over
PIXELS = SIDE * SIDE
WORK = PIXELS * 6 * 2  # the default 6 iterations at 2 samples: a third sample is over
CAMERA = {"eye": [0, 1, 4], "look_at": [0, 0.5, 0]}
STEREO = {**CAMERA, "stereo": "top-bottom"}
PATH = {"fps": 2, "keyframes": [{"t": 0, **CAMERA}, {"t": 1, **CAMERA, "eye": [0.5, 1, 4]}]}
STEREO_PATH = {**PATH, "keyframes": [{**k, "stereo": "top-bottom"} for k in PATH["keyframes"]]}

STEREO_REFUSAL = f"{SIDE}x{2 * SIDE} is more than the {PIXELS} pixels an image may have"
SIZE_REFUSAL = f"{SIDE + 2}x{SIDE} is more than the {PIXELS} pixels an image may have"
WORK_REFUSAL = (
    f"{SIDE}x{SIDE} pixels x 3 spp x 6 iterations is {PIXELS * 18:,} rays, more than the {WORK:,} one painting may "
    "take: ask for fewer pixels, samples or iterations"
)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    scenes = tmp_path_factory.mktemp("scenes")
    (scenes / "tiny.toml").write_text(SPINNING_BOX)
    data = tmp_path_factory.mktemp("data")
    with BackgroundServer(scenes=scenes, data=data, max_pixels=PIXELS, max_work=WORK, settle_ms=20) as live:
        yield live


def rest(server, **body) -> str:
    answer = httpx.post(f"{server.url}/api/render", json={"scene": "tiny", **body}, timeout=60)
    assert answer.status_code == 422, answer.text
    return answer.json()["detail"]


def video(server, **body) -> str:
    answer = httpx.post(f"{server.url}/api/videos", json={"scene": "tiny", **body}, timeout=60)
    assert answer.status_code == 422, answer.text
    return answer.json()["detail"]


def refusal(walk: Walk) -> str:
    """The walk's next error, past the frames and notes before it."""
    while (message := walk.next())["type"] != "error":
        if message["type"] == "frame":
            walk.ws.recv(30)  # its JPEG
    return message["message"]


def walking(server) -> Walk:
    """A walk that said hello within the limit and got its first frame."""
    walk = Walk(server)
    walk.send(type="hello", scene="tiny", width=SIDE, height=SIDE)
    assert walk.next()["type"] == "ready"
    walk.frame()
    return walk


def test_a_stereo_pair_over_the_pixels_is_refused_alike_by_every_door(server):
    assert rest(server, width=SIDE, height=SIDE, camera=STEREO) == STEREO_REFUSAL
    assert video(server, width=SIDE, height=SIDE, path=STEREO_PATH) == STEREO_REFUSAL
    walk = walking(server)
    try:
        walk.send(type="camera", id=7, **STEREO)
        assert refusal(walk) == STEREO_REFUSAL
        walk.send(type="camera", id=8, **CAMERA, fov=50)  # the walk goes on, as it was: one eye, its size
        while (meta := walk.frame()[0])["camera_id"] != 8 or not meta["final"]:
            assert (meta["width"], meta["height"]) != (SIDE, 2 * SIDE) and meta["camera_id"] != 7
        assert (meta["width"], meta["height"]) == (SIDE, SIDE)
    finally:
        walk.close()


def test_a_size_over_the_pixels_is_refused_alike_by_every_door(server):
    assert rest(server, width=SIDE + 2, height=SIDE) == SIZE_REFUSAL
    assert video(server, width=SIDE + 2, height=SIDE, path=PATH) == SIZE_REFUSAL
    walk = Walk(server)
    try:
        walk.send(type="hello", scene="tiny", width=SIDE + 2, height=SIDE)
        assert refusal(walk) == SIZE_REFUSAL
        walk.close()
        walk = walking(server)
        walk.send(type="view", width=SIDE + 2, height=SIDE)
        assert refusal(walk) == SIZE_REFUSAL
    finally:
        walk.close()


def test_samples_over_the_work_are_refused_alike_by_every_door(server):
    assert rest(server, width=SIDE, height=SIDE, paint={"spp": 3}) == WORK_REFUSAL
    assert video(server, width=SIDE, height=SIDE, path=PATH, paint={"spp": 3}) == WORK_REFUSAL
    walk = walking(server)
    try:
        walk.send(type="paint", spp=3)
        assert refusal(walk) == WORK_REFUSAL
    finally:
        walk.close()


def test_a_stereo_walk_refines_with_the_samples_both_eyes_afford(tmp_path):
    """The planner sizes a resting stereo walk's samples from the pixels of both eyes: the final refinement of
    a pair stays within the work one painting may take."""
    (tmp_path / "tiny.toml").write_text(SPINNING_BOX)
    work = 64 * 64 * 6 * 6  # 6 iterations: one eye affords 6 spp, a pair 3
    with BackgroundServer(scenes=tmp_path, data=tmp_path / "data", max_work=work, settle_ms=20) as live:
        walk = Walk(live)
        try:
            walk.send(type="hello", scene="tiny", width=64, height=64)
            assert walk.next()["type"] == "ready"
            assert walk.until_final()[-1][0]["spp"] == 4  # REFINE_SPP: the work would allow 6
            walk.send(type="camera", id=1, **STEREO)
            final = walk.until_final()[-1][0]
            assert (final["camera_id"], final["width"], final["height"], final["spp"]) == (1, 64, 128, 3)
        finally:
            walk.close()


def test_an_unknown_scene_is_refused_alike_by_every_door(server):
    line = "unknown scene 'nowhere'; known: tiny"
    for route, body in (
        ("/api/render", {"width": 32, "height": 32}),
        ("/api/videos", {"width": 32, "height": 32, "path": PATH}),
        ("/api/paths", {"path": PATH}),
    ):
        answer = httpx.post(f"{server.url}{route}", json={"scene": "nowhere", **body}, timeout=60)
        assert (answer.status_code, answer.json()) == (404, {"detail": line}), route
    walk = Walk(server)
    try:
        walk.send(type="hello", scene="nowhere", width=32, height=32)
        assert refusal(walk) == line
    finally:
        walk.close()


def test_a_full_queue_is_refused_with_its_status_its_line_and_a_time_to_try_again(tmp_path):
    """A 503 of every door says when to try again, in its line and in ``Retry-After``."""
    (tmp_path / "tiny.toml").write_text(SPINNING_BOX)
    long = {**PATH, "fps": 30, "keyframes": [PATH["keyframes"][0], {**PATH["keyframes"][1], "t": 60}]}
    body = {"scene": "tiny", "width": 64, "height": 48, "path": long}
    with BackgroundServer(scenes=tmp_path, data=tmp_path / "data", max_videos=1, max_videos_waiting=0) as live:
        assert httpx.post(f"{live.url}/api/videos", json=body, timeout=60).status_code == 202
        full = httpx.post(f"{live.url}/api/videos", json=body, timeout=60)
        assert full.status_code == 503 and full.headers["retry-after"] == "30"
        assert full.json() == {"detail": "the video queue is busy, every place in it taken; try again in 30 s"}


def test_a_walker_refused_at_hello_is_closed_at_once_with_the_reason_and_a_code_to_retry(tmp_path):
    """Refused for want of a place (here the server's walk-throughs; on Ray the cluster's room), the walker gets
    one error line and its socket closes with that reason and 1013 (try again later), long before the hello
    timeout would close it."""
    from websockets.exceptions import ConnectionClosed

    (tmp_path / "tiny.toml").write_text(SPINNING_BOX)
    line = "the server is at its limit of 1 walk-throughs; try again in 30 s"
    with BackgroundServer(scenes=tmp_path, data=tmp_path / "data", max_sessions=1, hello_timeout_s=3600) as live:
        first, second = Walk(live), Walk(live)  # both let in: neither holds a place yet
        try:
            first.send(type="hello", scene="tiny", width=32, height=32)
            assert first.next()["type"] == "ready"
            second.send(type="hello", scene="tiny", width=32, height=32)
            assert second.next() == {"type": "error", "message": line, "answers": "hello", "id": None}
            with pytest.raises(ConnectionClosed) as closed:
                second.next()
            assert (closed.value.rcvd.code, closed.value.rcvd.reason) == (1013, line)
        finally:
            first.close()
            second.close()
