"""The walk's view reducer alone, no socket: every message kind, taken and refused; a refusal leaves the view
as it was, in the line every door gives. And the outbox's bounds: the newest frame, move and pick win, and a
rate past its burst is refused (a fake clock)."""

from __future__ import annotations

import asyncio

import pytest
from helpers.scenes import CAMERA, make_scene

from rcp_server.service import protocol
from rcp_server.service.outbox import Outbox, Questions, Rate
from rcp_server.service.refusal import Refusal
from rcp_server.service.settings import Settings
from rcp_server.service.walkview import WalkView, another_picture, apply

SETTINGS = Settings(max_pixels=64 * 64, max_work=64 * 64 * 6 * 2)
SCENE = make_scene()


def find(name: str):
    if name != "test":
        raise Refusal(f"unknown scene {name!r}; known: test", 404)
    return SCENE


def take(view: WalkView, **message) -> WalkView | Refusal:
    return apply(view, protocol.client_message.validate_python(message), SETTINGS, find)


def hello() -> WalkView:
    view = take(WalkView(), type="hello", scene="test", width=32, height=32, quality=70)
    assert isinstance(view, WalkView)
    return view


def test_hello_opens_the_scene_with_its_camera_and_a_new_epoch():
    view = hello()
    assert (view.scene, view.camera, view.camera_id, view.epoch) == (SCENE, CAMERA, None, 1)
    assert (view.width, view.height, view.quality, view.overrides) == (32, 32, 70, {})
    assert view.params == SCENE.painting({})
    again = take(take(view, type="paint", spp=2), type="hello", scene="test", width=16, height=16)
    assert again.epoch == 2 and again.overrides == {} and again.params == SCENE.painting({})
    assert another_picture(view, again)


def test_a_bad_hello_is_refused_and_the_view_stays():
    empty = WalkView()
    unknown = take(empty, type="hello", scene="nowhere")
    assert isinstance(unknown, Refusal) and (unknown.status, unknown.message) == (
        404,
        "unknown scene 'nowhere'; known: test",
    )
    large = take(empty, type="hello", scene="test", width=66, height=64)
    assert isinstance(large, Refusal) and large.message == f"66x64 is more than the {64 * 64} pixels an image may have"


@pytest.mark.parametrize(
    "message",
    [
        {"type": "camera", "eye": [0, 1, 4], "look_at": [0, 0, 0]},
        {"type": "paint", "spp": 2},
        {"type": "mode", "temporal": True},
        {"type": "view", "width": 16},
    ],
)
def test_every_message_before_hello_is_refused(message):
    refused = take(WalkView(), **message)
    assert (
        isinstance(refused, Refusal)
        and refused.message == f"say hello first: a '{message['type']}' message needs a scene"
    )


def test_a_camera_is_taken_and_another_projection_is_another_picture():
    view = hello()
    moved = take(view, type="camera", id=4, eye=[1, 1, 4], look_at=[0, 0, 0])
    assert moved.camera_id == 4 and moved.camera.eye == (1.0, 1.0, 4.0) and not another_picture(view, moved)
    panorama = take(moved, type="camera", id=5, eye=[1, 1, 4], look_at=[0, 0, 0], projection="equirect")
    assert isinstance(panorama, Refusal)  # 32x32 is no equirect canvas: width must be 2 x height
    wide = take(
        take(view, type="view", width=64, height=32),
        type="camera",
        id=5,
        eye=[1, 1, 4],
        look_at=[0, 0, 0],
        projection="equirect",
    )
    assert isinstance(wide, WalkView) and another_picture(view, wide)


def test_a_bad_camera_is_refused_and_the_view_stays():
    view = hello()
    at_target = take(view, type="camera", eye=[0, 0, 0], look_at=[0, 0, 0])
    assert isinstance(at_target, Refusal) and at_target.status == 422
    large = take(
        take(view, type="view", width=64, height=64),
        type="camera",
        eye=[0, 1, 4],
        look_at=[0, 0, 0],
        stereo="top-bottom",
    )
    assert isinstance(large, Refusal) and large.message == f"64x128 is more than the {64 * 64} pixels an image may have"
    stereo = take(view, type="camera", eye=[0, 1, 4], look_at=[0, 0, 0], stereo="top-bottom", id=1)
    assert isinstance(stereo, WalkView) and stereo.camera.stereo == "top-bottom" and another_picture(view, stereo)


def test_paint_settings_add_up_and_null_restores_the_scenes():
    view = hello()
    painted = take(take(view, type="paint", spp=2), type="paint", lambda_p=5.0)
    assert painted.overrides == {"spp": 2, "lambda_p": 5.0} and painted.params.spp == 2
    restored = take(painted, type="paint", spp=None)
    assert restored.overrides == {"lambda_p": 5.0} and restored.params.spp == SCENE.painting({}).spp


def test_paint_settings_over_the_work_are_refused():
    refused = take(hello(), type="paint", spp=64)
    assert isinstance(refused, Refusal) and "more than the" in refused.message and refused.status == 422


def test_modes_and_views_change_only_what_they_name():
    view = take(hello(), type="mode", temporal=True)
    assert (view.temporal, view.animate) == (True, False)
    view = take(view, type="mode", animate=True)
    assert (view.temporal, view.animate) == (True, True)
    resized = take(view, type="view", width=48)
    assert (resized.width, resized.height, resized.quality) == (48, 32, 70)
    refused = take(view, type="view", width=128, height=64)
    assert (
        isinstance(refused, Refusal)
        and refused.message == f"128x64 is more than the {64 * 64} pixels an image may have"
    )


def test_the_outbox_keeps_the_newest_frame_and_the_notes_in_order():
    async def run() -> list[dict]:
        outbox = Outbox()
        outbox.note(protocol.Error(message="one"))
        meta = protocol.Frame(
            seq=0, width=1, height=1, render_ms=1.0, iteration=1, spp=1, scale=1.0, phase="walk", final=False,
            temporal=False, quality=70, paint={}, camera_id=None, time=0.0, dropped=0,
        )  # fmt: skip
        outbox.post_frame(meta, [b"old"])
        outbox.post_frame(meta, [b"new"])
        outbox.note(protocol.Error(message="two"))
        return await outbox.take()

    sent = asyncio.run(run())
    assert [m.get("bytes") for m in sent] == [None, None, None, b"new"]
    assert '"dropped":1' in sent[2]["text"] and '"seq":2' in sent[2]["text"]


def test_the_newest_move_and_pick_replace_those_waiting():
    async def run() -> list:
        questions = Questions()
        for k in range(5):
            questions.ask(protocol.MoveMessage(type="move", id=k, eye=(0, 0, 0), delta=(0, 0, 1)))
            questions.ask(protocol.PickMessage(type="pick", x=k, y=k))
        return [await questions.next(), await questions.next(), questions.replaced]

    move, pick, replaced = asyncio.run(run())
    assert (move.id, pick.x, replaced) == (4, 4, 8)


def test_a_rate_allows_its_burst_then_its_pace():
    now = [0.0]
    rate = Rate(10.0, 40.0, lambda: now[0])
    assert all(rate.allows() for _ in range(40)) and not rate.allows()
    now[0] += 0.5
    assert sum(rate.allows() for _ in range(10)) == 5
