"""The WebSocket walk-through against a real server on loopback: hello, frames, refinement, the newest camera
wins, temporal painting, bad messages, the session limit."""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest
from helpers.servers import BackgroundServer
from helpers.waits import wait_until
from helpers.wire import decode, post


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
        wait_until(lambda: not httpx.get(f"{server.url}/api/health").json()["sessions"])
        third = walk_to(server)
        third.send(type="hello", scene="sky", width=32, height=18)
        assert third.next()["type"] == "ready"
        third.close()


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


CAMERA = {"eye": [0.8, 1.7, 38.0], "look_at": [0.0, 3.0, 0.0]}


def _walk_frames_of_one_camera(walk, ids: range) -> list[tuple[dict, bytes]]:
    """The walk frame of each camera message in ``ids``, all of one camera, those of the size most of them
    have (the planner sizes walk frames to the machine's speed)."""
    frames = []
    for k in ids:
        walk.send(type="camera", id=k, **CAMERA)
        while (meta := walk.next())["type"] != "frame" or meta["camera_id"] != k or meta["phase"] != "walk":
            if meta["type"] == "frame":
                walk.ws.recv(30)  # a refinement, or an older camera's frame
        frames.append((meta, walk.ws.recv(30)))
    widths = [meta["width"] for meta, _ in frames]
    return [(meta, jpeg) for meta, jpeg in frames if meta["width"] == max(set(widths), key=widths.count)]


def test_boil_reseeds_walk_frames_and_leaves_the_rest_painting_be(walk, live_server):
    """``boil = 1``: consecutive walk frames of one camera differ in their noise, each the still of its own
    seed (the seed moved on by one a walk frame, as a film's frames are); ``boil = 0``: they are the same frame.
    The refinement at rest is the view's still, which does not boil."""
    walk.send(type="hello", scene="default", width=64, height=36)
    walk.next()
    walk.send(type="paint", noise=0.4, boil=1)
    walk.until_final()
    boiled = _walk_frames_of_one_camera(walk, range(6))
    assert len(boiled) >= 3
    seeds = [meta["paint"]["seed"] for meta, _ in boiled]
    assert all(b > a for a, b in zip(seeds, seeds[1:], strict=False))
    assert all(a != b for (_, a), (_, b) in zip(boiled, boiled[1:], strict=False))
    meta, jpeg = boiled[-1]
    body = {"scene": "default", "width": meta["width"], "height": meta["height"], "camera": CAMERA}
    body |= {"paint": meta["paint"], "format": "jpeg", "quality": meta["quality"]}
    assert post(live_server, body).content == jpeg
    refined = walk.until_final()[-1][0]
    assert refined["phase"] == "refine" and refined["paint"]["seed"] not in seeds  # the scene's seed: the still's
    walk.send(type="paint", boil=0)
    walk.until_final()
    still = _walk_frames_of_one_camera(walk, range(6, 12))
    assert len(still) >= 3 and len({jpeg for _, jpeg in still}) == 1
    assert {meta["paint"]["seed"] for meta, _ in still} == {refined["paint"]["seed"]}
