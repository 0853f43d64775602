"""The service against a real server on loopback: REST renders, the WebSocket walk-through, the protocol."""

from __future__ import annotations

import json
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import httpx
import numpy as np
import pytest

from rcp_server import images
from rcp_server.bench.harness import BackgroundServer
from rcp_server.camera import Camera
from rcp_server.painting import paint
from rcp_server.service import protocol
from rcp_server.service.workshop import FairPool

from .conftest import decode

ROOT = Path(__file__).resolve().parents[2]


def post(server, body: dict) -> httpx.Response:
    return httpx.post(f"{server.url}/api/render", json=body, timeout=120)


# ---- REST ----


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
        time.sleep(0.2)
        clock = time.perf_counter()
        assert httpx.get(f"{live_server.url}/api/health", timeout=10).status_code == 200
        answered = time.perf_counter() - clock
        assert not all(r.done() for r in renders)  # health answered while both paintings ran
        assert all(r.result().status_code == 200 for r in renders)
    assert answered < 1.0


def test_openapi_documents_the_render_body(live_server):
    schema = httpx.get(f"{live_server.url}/openapi.json").json()
    assert "/api/render" in schema["paths"] and "RenderRequest" in schema["components"]["schemas"]
    assert httpx.get(f"{live_server.url}/docs").status_code == 200


# ---- the fair pool ----


def test_fair_pool_takes_paintings_in_turns():
    pool = FairPool(1)
    order: list[str] = []
    gate = threading.Event()
    pool.submit(gate.wait)  # hold the only worker while both batches queue
    first = pool.map(order.append, [f"a{k}" for k in range(3)])
    second = pool.map(order.append, [f"b{k}" for k in range(3)])
    gate.set()
    list(first), list(second)
    pool.shutdown()
    assert order == ["a0", "b0", "a1", "b1", "a2", "b2"]


def test_fair_pool_background_lane_takes_what_the_foreground_leaves():
    pool = FairPool(1)
    order: list[str] = []
    gate, painting, hold = threading.Event(), threading.Event(), threading.Event()

    def tile(name: str) -> None:
        order.append(name)
        if name == "v0":  # a video tile in progress keeps the worker while a walk frame comes
            painting.set()
            hold.wait(10)

    pool.submit(gate.wait, 10)
    video = pool.background.map(tile, [f"v{k}" for k in range(3)])  # queued before the walk's
    walk = pool.map(tile, ["w0", "w1"])
    gate.set()
    list(walk)
    assert painting.wait(10)
    later = pool.map(tile, ["w2"])
    hold.set()
    list(video), list(later)
    pool.shutdown()
    assert order == ["w0", "w1", "v0", "w2", "v1", "v2"]


def test_fair_pool_passes_errors_and_drops_the_rest_of_a_failed_batch():
    pool = FairPool(1)
    gate = threading.Event()
    pool.submit(gate.wait)
    ran = []
    failed = threading.Event()

    def work(k):
        ran.append(k)
        if k == 0:
            raise KeyError(k)
        failed.wait(10)  # tile 1 runs on while the caller sees the error and drops tiles 2 and 3

    results = pool.map(work, range(4))
    gate.set()
    with pytest.raises(KeyError):
        list(results)
    failed.set()
    pool.shutdown()
    assert ran == [0, 1]


# ---- the WebSocket walk-through ----


def test_hello_gives_ready_then_walk_and_refined_frames(walk):
    walk.send(type="hello", scene="default", width=160, height=90)
    ready = walk.next()
    assert ready["type"] == "ready" and ready["scene"]["name"] == "default" and not ready["temporal"]
    frames = walk.until_final()
    first, last = frames[0][0], frames[-1][0]
    assert first["phase"] == "walk" and last["phase"] == "refine" and last["spp"] >= 4
    assert (last["width"], last["height"]) == (160, 90) and frames[-1][1].shape == (90, 160, 3)
    assert [m["seq"] for m, _ in frames] == list(range(1, len(frames) + 1))
    for meta, image in frames:
        assert image.shape == (meta["height"], meta["width"], 3) and meta["render_ms"] > 0


def test_refined_frame_is_the_rest_painting(walk, live_server):
    """At rest the walk-through shows what a REST render of the same view gives (what Save downloads)."""
    walk.send(type="hello", scene="default", width=96, height=54, quality=100)
    walk.next()
    refined = [m for m in walk.until_final() if m[0]["phase"] == "refine"]
    meta, image = refined[0]
    body = {"scene": "default", "width": 96, "height": 54, "paint": {"spp": meta["spp"]}}
    expected = decode(post(live_server, body).content).astype(int)
    assert np.abs(image.astype(int) - expected).mean() < 2.0  # JPEG at quality 100


def test_camera_messages_are_coalesced_and_the_newest_wins(walk):
    walk.send(type="hello", scene="default", width=160, height=90)
    walk.next()
    walk.until_final()
    for k in range(60):
        walk.send(type="camera", eye=[0.8, 1.7, 38.0 - 0.2 * k], look_at=[0.0, 3.0, 0.0], id=k)
    frames = walk.until_final()
    assert len(frames) < 30  # far fewer frames than camera messages
    assert frames[-1][0]["camera_id"] == 59  # and the last shows the newest camera
    ids = [m["camera_id"] for m, _ in frames]
    assert ids == sorted(ids)


def test_walk_frames_are_the_rest_paintings_of_their_cameras(walk, live_server):
    """Walking, every frame is the painting of its camera at the frame's size and settings: the very JPEG
    that ``POST /api/render`` gives for them."""
    walk.send(type="hello", scene="default", width=320, height=180)
    walk.next()
    walk.until_final()
    cameras = {k: {"eye": [0.8 + 0.3 * k, 1.7, 38.0 - k], "look_at": [0.0, 3.0, 0.0]} for k in range(3)}
    seen = 0
    for k, camera in cameras.items():
        walk.send(type="camera", id=k, **camera)
        while (meta := walk.next())["type"] != "frame" or meta["camera_id"] != k:
            if meta["type"] == "frame":
                walk.ws.recv(30)  # an older camera's frame
        jpeg = walk.ws.recv(30)
        assert meta["phase"] == "walk" and not meta["temporal"] and meta["iteration"] == meta["paint"]["iterations"]
        assert meta["paint"]["spp"] == meta["spp"] == 1 and meta["quality"] <= 70
        body = {
            "scene": "default",
            "width": meta["width"],
            "height": meta["height"],
            "camera": camera,
            "paint": meta["paint"],
            "format": "jpeg",
            "quality": meta["quality"],
        }
        assert post(live_server, body).content == jpeg
        seen += 1
    assert seen == 3


def test_temporal_walk_frames_continue_the_recursion(walk):
    walk.send(type="hello", scene="default", width=160, height=90)
    walk.next()
    walk.send(type="mode", temporal=True)
    walk.until_final()
    iterations = []
    for k in range(4):
        walk.send(type="camera", eye=[0.8 + 0.05 * k, 1.7, 38.0], look_at=[0.0, 3.0, 0.0], id=k)
        meta, _ = walk.frame()
        iterations.append(meta["iteration"])
        assert meta["phase"] == "walk" and meta["temporal"] and meta["spp"] == 1
    assert all(b > a for a, b in zip(iterations, iterations[1:], strict=False))
    walk.send(type="mode", temporal=False)
    meta, _ = walk.frame()
    assert not meta["temporal"] and meta["iteration"] == 6


def test_paint_message_changes_the_painting(walk):
    walk.send(type="hello", scene="default", width=128, height=72)
    walk.next()
    before = walk.until_final()[-1][1].astype(int)
    walk.send(type="paint", lambda_p=0.0)
    after = walk.until_final()[-1][1].astype(int)
    assert np.abs(after - before).mean() > 1.0
    walk.send(type="paint", lambda_p=None)  # back to the scene's default
    again = walk.until_final()[-1][1].astype(int)
    assert np.abs(again - before).mean() < 1.0


@pytest.mark.parametrize(
    ("message", "says"),
    [
        ("not json", "bad message"),
        (json.dumps({"type": "teleport"}), "teleport"),
        (json.dumps({"type": "camera", "eye": [0, 0, 0], "look_at": [0, 0, 0]}), "eye"),
        (json.dumps({"type": "camera", "eye": [0, 0], "look_at": [0, 0, 1]}), "eye"),
        (json.dumps({"type": "paint", "spp": -1}), "spp"),
        (json.dumps({"type": "paint", "mapping": "sepia"}), "mapping"),
        (json.dumps({"type": "hello", "scene": "atlantis"}), "unknown scene"),
        (json.dumps({"type": "view", "width": 4096, "height": 4096}), "pixels"),
    ],
)
def test_bad_messages_get_an_error_and_the_session_goes_on(walk, message, says):
    walk.send(type="hello", scene="sky", width=64, height=36)
    walk.next()
    walk.until_final()
    walk.ws.send(message)
    error = walk.next()
    assert error["type"] == "error" and says in error["message"]
    walk.send(type="camera", eye=[0, 0, 0], look_at=[0, 1, 1], id=7)
    assert walk.until_final()[-1][0]["camera_id"] == 7


def test_messages_before_hello_and_binary_messages_are_refused(walk):
    walk.send(type="camera", eye=[0, 0, 0], look_at=[0, 0, 1])
    assert "hello first" in walk.next()["message"]
    walk.ws.send(b"\x00\x01")
    assert "JSON text" in walk.next()["message"]
    walk.send(type="hello", scene="sky", width=32, height=18)
    assert walk.next()["type"] == "ready"


def test_sessions_are_limited_and_freed_on_disconnect(walk_to):
    with BackgroundServer(max_sessions=1, settle_ms=50) as server:
        first = walk_to(server)
        first.send(type="hello", scene="sky", width=32, height=18)
        first.next()
        second = walk_to(server)
        assert "limit" in second.next()["message"]
        with pytest.raises(Exception):  # noqa: B017 - the server closes the socket (code 1013)
            second.next(5)
        first.close()
        deadline = time.monotonic() + 10
        while httpx.get(f"{server.url}/api/health").json()["sessions"] and time.monotonic() < deadline:
            time.sleep(0.05)
        third = walk_to(server)
        third.send(type="hello", scene="sky", width=32, height=18)
        assert third.next()["type"] == "ready"
        third.close()


# ---- the protocol ----


def test_client_protocol_module_is_generated_from_the_server_models():
    assert (ROOT / "client" / "protocol.js").read_text() == protocol.client_module()


def test_camera_message_builds_the_same_camera_as_the_engine():
    message = protocol.client_message.validate_json(
        json.dumps({"type": "camera", "eye": [1, 2, 3], "look_at": [0, 0, 0]})
    )
    assert Camera(message.eye, message.look_at, message.up, message.fov) == Camera((1, 2, 3), (0, 0, 0))


# ---- rcp serve ----


def test_rcp_serve_takes_its_port_from_the_environment_and_stops_cleanly():
    import os
    import signal
    import subprocess
    import sys

    from rcp_server.bench.harness import free_port

    port = free_port()
    env = {**os.environ, "RCP_PORT": str(port)}
    server = subprocess.Popen([sys.executable, "-m", "rcp_server.cli", "serve"], env=env, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                health = httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1)
                break
            except httpx.TransportError:
                assert server.poll() is None and time.monotonic() < deadline, "rcp serve did not come up"
                time.sleep(0.2)
        assert health.json()["status"] == "ok"
        assert "<canvas" in httpx.get(f"http://127.0.0.1:{port}/").text  # the client, at /
    finally:
        server.send_signal(signal.SIGINT)
        assert server.wait(30) == 0
    assert b"serving 3 scenes" in server.stderr.read()


@pytest.mark.parametrize("argv", [["serve", "--port", "70000"], ["serve", "--port", "http"]])
def test_rcp_serve_refuses_a_bad_port_in_one_line(argv, capsys):
    from rcp_server.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("rcp: error:") and err.count("\n") == 1 and "port" in err


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


def test_walk_through_paints_with_the_image_method(walk):
    walk.send(type="hello", scene="default", width=128, height=72)
    walk.next()
    walk.until_final()
    walk.send(type="paint", method="image")
    walk.send(type="camera", eye=[1.0, 1.7, 37.0], look_at=[0.0, 3.0, 0.0], id=1)
    frames = walk.until_final()
    assert frames[-1][0]["camera_id"] == 1 and frames[-1][1].shape == (72, 128, 3)
    walk.send(type="paint", lambda_e=0.1)
    assert "eye displacement" in walk.next()["message"]


def test_after_a_second_hello_every_frame_shows_the_new_scene(walk):
    walk.send(type="hello", scene="default", width=160, height=90)
    walk.next()
    walk.frame()
    walk.send(type="hello", scene="sky", width=40, height=40)  # square, while the 16:9 village still refines
    while (message := walk.next())["type"] != "ready":
        if message["type"] == "frame":
            walk.ws.recv(30)
    assert message["scene"]["name"] == "sky"
    assert all(meta["width"] == meta["height"] for meta, _ in walk.until_final())  # no village frame after ready
