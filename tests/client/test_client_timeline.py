"""The camera path's timeline in a real headless Chromium against a real server: a key dragged to retime it,
values typed into the selected key (camera, ease, painting), undo and redo, scrubbing (the walk shows the
server's camera at that time), and the path saved and loaded as the JSON ``rcp render --path`` reads."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.browser import needs_chromium

from rcp_server.media.camerapath import parse_path
from rcp_server.scene.scenefile import load_scene

WAIT_MS = 60_000
pytestmark = needs_chromium
SIDE = {"eye": [0, 1.6, 0], "look_at": [3, 1.6, -3], "up": [0, 1, 0], "fov": 50}
AHEAD = {"eye": [0, 1.6, -4], "look_at": [0, 1.6, -8], "up": [0, 1, 0], "fov": 60}


@pytest.fixture
def page(browser, live_server, tmp_path):
    context = browser.new_context(viewport={"width": 1024, "height": 900}, accept_downloads=True)
    page = context.new_page()
    problems = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(f"{live_server.url}/?scene=sky&width=64&height=48")
    page.wait_for_function("rcp.state.scene !== null && rcp.overlay.frame", timeout=WAIT_MS)
    yield page
    page.screenshot(path=str(tmp_path / "timeline.png"))
    context.close()
    assert problems == [], f"console errors: {problems}"


def keys(page) -> list[dict]:
    return page.evaluate("rcp.path.path.keyframes")


def three_keys(page) -> None:
    add = page.locator("#path [data-path=add]")
    for camera in (SIDE, AHEAD, SIDE):
        page.evaluate(f"rcp.walk.place({json.dumps(camera)})")
        add.click()
    assert [k["t"] for k in keys(page)] == [0, 1, 2]


def test_a_key_dragged_on_the_timeline_is_retimed_and_undone(page):
    three_keys(page)
    middle = page.locator("#path [data-path=timeline] [data-index='1']")
    track = page.locator("#path [data-path=timeline]").bounding_box()
    box = middle.bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(track["x"] + track["width"] * 0.25, box["y"] + box["height"] / 2, steps=8)
    page.mouse.up()
    times = [k["t"] for k in keys(page)]
    assert times[0] == 0 and times[2] == 2 and times[1] == pytest.approx(0.5, abs=0.05)
    assert page.evaluate("rcp.path.selected") == 1
    # undo puts it back, redo retimes it again
    page.locator("#path [data-path=undo]").click()
    assert [k["t"] for k in keys(page)] == [0, 1, 2]
    page.locator("#path [data-path=redo]").click()
    assert [k["t"] for k in keys(page)] == times
    # dragged past its neighbour, a key stops short of it
    box = middle.bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(track["x"] + track["width"] + 50, box["y"] + box["height"] / 2, steps=8)
    page.mouse.up()
    assert keys(page)[1]["t"] == pytest.approx(1.99)


def test_values_typed_into_the_selected_key_save_as_the_cli_reads_them(page, tmp_path, live_server):
    three_keys(page)
    page.locator("#path [data-path=timeline] [data-index='2']").click()
    editor = page.locator("#path [data-path=editor]")
    editor.locator("[data-field='fov']").fill("35")
    editor.locator("[data-field='fov']").dispatch_event("change")
    editor.locator("[data-field='eye.0']").fill("1.5")
    editor.locator("[data-field='eye.0']").dispatch_event("change")
    editor.locator("[data-field='ease.0']").fill("1")
    editor.locator("[data-field='ease.0']").dispatch_event("change")
    editor.locator("[data-field='paint']").fill('{"lambda_p": 3, "style": "smudge"}')
    editor.locator("[data-field='paint']").dispatch_event("change")
    editor.locator("[data-field='fade']").fill("0.5")
    editor.locator("[data-field='fade']").dispatch_event("change")
    last = keys(page)[2]
    assert (last["fov"], last["eye"][0], last["ease"], last["paint"], last["fade"]) == (
        35, 1.5, [1, 0], {"lambda_p": 3, "style": "smudge"}, 0.5)  # fmt: skip
    # two undos take back the fade and the painting; a redo brings the painting again
    page.locator("#path [data-path=undo]").click()
    page.locator("#path [data-path=undo]").click()
    assert "paint" not in keys(page)[2] and "fade" not in keys(page)[2] and keys(page)[2]["fov"] == 35
    page.locator("#path [data-path=redo]").click()
    assert keys(page)[2]["paint"] == {"lambda_p": 3, "style": "smudge"}
    # saved: the JSON the command line reads, with its ease and painting
    with page.expect_download() as saved:
        page.locator("#path [data-path=save]").click()
    file = tmp_path / "path.json"
    saved.value.save_as(file)
    written = json.loads(file.read_text())
    assert written["keyframes"] == keys(page)
    scene = load_scene("sky")
    resolved = parse_path(written).resolve(scene.camera).with_painting(scene.paint, scene.check_names)
    assert resolved.eases[2] == (1.0, 0.0) and resolved.track is not None
    # and loaded back into an emptied path
    page.locator("#path [data-path=clear]").click()
    page.locator("#path [data-path=file]").set_input_files(str(file))
    page.wait_for_function("rcp.path.path.keyframes.length === 3", timeout=WAIT_MS)
    assert keys(page) == written["keyframes"]


def test_scrubbing_shows_the_paths_camera_at_that_time(page, live_server):
    three_keys(page)
    scrub = page.locator("#path [data-path=scrub]")
    scrub.fill("0.5")
    page.wait_for_function("rcp.path.scrubbed !== null && rcp.path.scrubbed.t === 0.5", timeout=WAIT_MS)
    assert page.evaluate("rcp.path.scrubbed.frame") == 12  # 0.5 s at 24 fps
    spec = page.evaluate("rcp.path.spec()")
    scene = load_scene("sky")
    (expected,), _ = parse_path(spec).resolve(scene.camera).at([0.5])
    page.wait_for_function(
        f"rcp.state.lastCamera && Math.abs(rcp.state.lastCamera.eye[2] - ({expected.eye[2]})) < 1e-3", timeout=WAIT_MS
    )
    shown = page.evaluate("rcp.state.lastCamera")
    assert shown["eye"] == pytest.approx(list(expected.eye), abs=1e-3)
    assert shown["fov"] == pytest.approx(expected.fov, abs=1e-3)
    # the walk paints that view: a frame comes for the scrubbed camera
    page.wait_for_function(
        f"rcp.overlay.frame && Math.abs(rcp.state.lastCamera.eye[2] - ({expected.eye[2]})) < 1e-3", timeout=WAIT_MS
    )


def test_an_uploaded_models_animated_camera_becomes_the_path(page):
    from helpers.gltf import animated_camera, expected_camera

    glb = animated_camera().glb()
    page.set_input_files("#upload-file", files=[{"name": "Shot.glb", "mimeType": "model/gltf-binary", "buffer": glb}])
    page.wait_for_function("rcp.state.scene?.uploaded === true", timeout=WAIT_MS)
    assert page.evaluate("rcp.state.scene.motions") == ["Shot"]
    page.locator("#path [data-path=fps]").fill("4")
    page.locator("#path [data-path=motion]").focus()
    page.locator("#path [data-path=use-motion]").click()
    page.wait_for_function("rcp.path.path.keyframes.length === 11", timeout=WAIT_MS)  # 0 to 2.5 s at 4 fps
    taken = keys(page)
    eye, *_, fov = expected_camera([k["t"] for k in taken])
    assert [k["t"] for k in taken] == [k / 4 for k in range(11)]
    np.testing.assert_allclose([k["eye"] for k in taken], eye, atol=1e-6)
    assert [k["fov"] for k in taken] == pytest.approx(fov.tolist(), abs=1e-5)  # the file holds float32 radians
    page.locator("#path [data-path=undo]").click()
    assert keys(page) == []


def keyed_path(page, tmp_path, keyframes: list[dict], loop: bool):
    """Loads a path of ``keyframes`` into the page from its file; returns the film's frames of it (each with
    its keyed painting, ``looks``), as ``rcp render --path`` would paint them."""
    file = tmp_path / "keyed.json"
    file.write_text(json.dumps({"fps": 24, "loop": loop, "keyframes": keyframes}))
    page.locator("#path [data-path=file]").set_input_files(str(file))
    page.wait_for_function(f"rcp.path.path.keyframes.length === {len(keyframes)}", timeout=WAIT_MS)
    scene = load_scene("sky")
    return parse_path(page.evaluate("rcp.path.spec()")).resolve(scene.camera).with_painting(scene.painting({})).frames()


def test_scrubbing_paints_the_paths_keyed_painting_at_that_time(page, tmp_path):
    """A path that keys its painting, loaded from its file: the frame shown at a scrubbed time is painted with
    the film's painting of that frame (a setting between two keys on its curve; within a fade, the steps of the
    style it fades to), and once the walk moves on the page's own painting comes back."""
    keyframes = [
        {"t": 0, **SIDE, "paint": {"lambda_p": 2, "noise": 0}},
        {"t": 1, **AHEAD, "paint": {"lambda_p": 20, "noise": 0.5}},
        {"t": 2, **SIDE, "paint": {"style": "layered"}, "fade": 1},
    ]
    films = {shot.index: shot for shot in keyed_path(page, tmp_path, keyframes, loop=False)}
    scene = load_scene("sky")
    scrub = page.locator("#path [data-path=scrub]")
    for t, frame in ((0.5, 12), (1.5, 36)):
        scrub.fill(str(t))
        page.wait_for_function(f"rcp.path.scrubbed?.t === {t}", timeout=WAIT_MS)
        assert page.evaluate("rcp.path.scrubbed.frame") == frame
        painting = films[frame].looks[-1][0]  # the film's frame: within the fade, the look it fades to
        # the walk's frame of the scrubbed camera names the film's painting of that frame
        page.wait_for_function(
            "rcp.overlay.frame?.camera_id === rcp.state.cameraId && rcp.state.keyed !== null"
            f" && Math.abs(rcp.overlay.frame.paint.lambda_p - {painting.lambda_p}) < 1e-9",
            timeout=WAIT_MS,
        )
        shown = page.evaluate("rcp.overlay.frame.paint")
        assert shown["noise"] == pytest.approx(painting.noise, abs=1e-9)
        assert (shown["mapping"], shown["iterations"]) == (painting.mapping, painting.iterations)
        assert page.evaluate("rcp.state.paint") == {}  # the page's own settings stay its own
    assert 2 < films[12].looks[0][0].lambda_p < 20  # between its keys, on their curve (PCHIP: within them)
    assert len(films[36].looks) == 2 and films[36].looks[-1][0].mapping == "normal"  # in the fade to layered
    sent = page.evaluate("rcp.sent.filter((m) => m.type === 'paint').at(-1)")
    assert sent["mapping"] == "normal" and sent["lambda_p"] == pytest.approx(films[36].looks[-1][0].lambda_p)
    # the walk moves on: the page's own painting again, for every setting the path keyed
    page.evaluate(f"rcp.walk.place({json.dumps({**AHEAD, 'fov': 55})})")
    page.wait_for_function("rcp.state.keyed === null", timeout=WAIT_MS)
    restored = page.evaluate("rcp.sent.filter((m) => m.type === 'paint').at(-1)")
    assert restored["lambda_p"] is None and restored["mapping"] is None and restored["noise"] is None
    own = scene.painting({})
    page.wait_for_function(
        f"rcp.overlay.frame?.camera_id === rcp.state.cameraId && rcp.overlay.frame.paint.lambda_p === {own.lambda_p}"
        f" && rcp.overlay.frame.paint.mapping === {json.dumps(own.mapping)}",
        timeout=WAIT_MS,
    )


def test_playback_paints_each_frame_with_the_paths_keyed_painting(page, tmp_path):
    """Played back, a path that keys its painting paints each frame as the film does: the painting asked for
    the frame being played is the film's painting of that frame."""
    keyframes = [
        {"t": 0, **SIDE, "paint": {"lambda_p": 2}},
        {"t": 2, **AHEAD, "paint": {"lambda_p": 20}},
    ]
    films = {shot.index: shot.looks[-1][0] for shot in keyed_path(page, tmp_path, keyframes, loop=True)}
    page.locator("#path [data-path=play]").click()
    page.wait_for_function("rcp.path.player.playing?.frame > 12 && rcp.state.keyed !== null", timeout=WAIT_MS)
    # the frame placed and the painting it keys, read at one moment (the next step may place the next frame)
    frame, keyed, sent = page.evaluate(
        "[rcp.path.player.playing.frame, rcp.state.keyed.paint,"
        " rcp.sent.filter((m) => m.type === 'paint' && m.lambda_p !== null).map((m) => m.lambda_p)]"
    )
    page.locator("#path [data-path=play]").click()  # stop
    assert 2 < films[frame].lambda_p < 20
    assert keyed["lambda_p"] == pytest.approx(films[frame].lambda_p)
    # and the server was asked for the played frames' paintings (sent with the frame after a step)
    played = [films[f].lambda_p for f in range(frame + 1)]
    assert sent and all(any(abs(value - p) < 1e-9 for p in played) for value in sent)
    assert page.evaluate("rcp.state.paint") == {}  # the page's own settings stay its own
