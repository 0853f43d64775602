"""The client's camera path in a real headless Chromium against a real server: keyframes added, moved and
deleted at the current view, recorded while walking, played back as the server interpolates them, saved and
loaded as JSON, and rendered to an MP4 with a progress bar and a download."""

from __future__ import annotations

import io
import json
from pathlib import Path

import av
import pytest
from helpers.browser import chromium, needs_chromium

WAIT_MS = 60_000

pytestmark = needs_chromium

SIDE = {"eye": [0, 1.6, 0], "look_at": [3, 1.6, -3], "up": [0, 1, 0], "fov": 50}


@pytest.fixture
def page(live_server, tmp_path):
    with chromium() as browser:
        context = browser.new_context(viewport={"width": 1024, "height": 900}, accept_downloads=True)
        page = context.new_page()
        problems = []
        page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.goto(f"{live_server.url}/?scene=sky&width=64&height=48")
        page.wait_for_function("rcp.state.scene !== null && rcp.overlay.frame", timeout=WAIT_MS)
        yield page
        page.screenshot(path=str(tmp_path / "path.png"))
        context.close()
        browser.close()
    assert problems == [], f"console errors: {problems}"


def keyframes(page) -> list[dict]:
    return page.evaluate("rcp.path.path.keyframes")


def test_keyframes_play_save_load_and_render(page, tmp_path):
    button = page.locator("#path [data-path=add]")
    button.click()
    page.evaluate(f"rcp.walk.place({json.dumps(SIDE)})")
    button.click()
    button.click()
    assert [k["t"] for k in keyframes(page)] == [0, 1, 2]
    first, second = keyframes(page)[:2]
    assert second["eye"] == SIDE["eye"] and second["fov"] == SIDE["fov"]
    assert abs(second["look_at"][0] - second["look_at"][2] * -1) < 1e-3  # looking along (1, 0, -1)
    # delete the third, move the first to the current view and back to where it was
    page.locator("#path li[data-index='2'] button[title^=Delete]").click()
    page.locator("#path li[data-index='0'] button[title^=Move]").click()
    assert keyframes(page)[0]["eye"] == SIDE["eye"]
    page.evaluate(f"rcp.walk.place({json.dumps({k: first[k] for k in ('eye', 'look_at', 'up', 'fov')})})")
    page.locator("#path li[data-index='0'] button[title^=Move]").click()
    assert keyframes(page) == [first, second]
    assert "2 keyframes · 1.0 s" in page.text_content("#path")

    # play: the walk follows the server's cameras to the last keyframe, then stops
    page.locator("#path [data-path=play]").click()
    page.wait_for_function("rcp.path.playing !== null", timeout=WAIT_MS)
    page.wait_for_function("rcp.path.playing === null", timeout=WAIT_MS)
    shown = page.evaluate("rcp.state.lastCamera")
    assert shown["eye"] == pytest.approx(SIDE["eye"], abs=1e-3)
    assert page.evaluate("rcp.sent.filter((m) => m.type === 'camera').length") >= 10  # frames in between

    # save, then load it back into an empty path
    with page.expect_download() as saved:
        page.locator("#path [data-path=save]").click()
    file = tmp_path / "walk.json"
    saved.value.save_as(file)
    assert json.loads(file.read_text()) == {"fps": 24, "loop": False, "keyframes": [first, second]}
    page.locator("#path [data-path=clear]").click()
    assert keyframes(page) == []
    page.locator("#path [data-path=file]").set_input_files(str(file))
    page.wait_for_function("rcp.path.path.keyframes.length === 2", timeout=WAIT_MS)
    assert keyframes(page) == [first, second]

    # render: a progress bar, then the MP4 to download
    page.locator("#path-fps").fill("8")
    page.locator("#path [data-path=render]").click()
    page.wait_for_selector("#path progress", state="visible", timeout=WAIT_MS)
    link = page.wait_for_selector("#path [data-path=download]:not([hidden])", timeout=WAIT_MS)
    assert page.evaluate("document.querySelector('#path progress').value") == 9
    assert page.text_content("#path [data-path=status]") == "done"
    with page.expect_download() as video:
        link.click()
    data = Path(video.value.path()).read_bytes()
    with av.open(io.BytesIO(data)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == 9 and frames[0].shape == (48, 64, 3)


def test_recording_takes_keyframes_while_walking(page):
    page.locator("#path [data-path=record]").click()
    page.evaluate(f"rcp.walk.place({json.dumps(SIDE)})")
    page.wait_for_function("rcp.path.path.keyframes.length >= 3", timeout=WAIT_MS)
    page.locator("#path [data-path=record]").click()
    times = [k["t"] for k in keyframes(page)]
    assert times[0] == 0 and all(b > a for a, b in zip(times, times[1:], strict=False))
    assert keyframes(page)[-1]["eye"] == SIDE["eye"]
    assert page.get_attribute("#path [data-path=record]", "aria-pressed") == "false"


def test_a_recorded_path_saved_loaded_and_rendered_at_a_chosen_size_with_a_moving_progress_bar(live_server, tmp_path):
    with chromium() as browser:
        context = browser.new_context(viewport={"width": 1024, "height": 900}, accept_downloads=True)
        page = context.new_page()
        problems = []
        page.on("pageerror", lambda e: problems.append(str(e)))
        page.goto(f"{live_server.url}/?scene=default&width=64&height=48&iterations=2")
        page.wait_for_function("rcp.state.scene !== null && rcp.overlay.frame", timeout=WAIT_MS)
        # K takes a keyframe where the walk stands
        page.click("#view", position={"x": 300, "y": 300})
        page.keyboard.press("k")
        assert len(keyframes(page)) == 1
        page.locator("#path [data-path=clear]").click()
        # record while walking
        page.locator("#path [data-path=record]").click()
        page.evaluate("rcp.walk.place({eye: [0.8, 1.7, 36], look_at: [0, 3, 0], up: [0, 1, 0], fov: 60})")
        page.wait_for_function("rcp.path.path.keyframes.length >= 3", timeout=WAIT_MS)
        page.locator("#path [data-path=record]").click()
        recorded = keyframes(page)
        with page.expect_download() as saved:
            page.locator("#path [data-path=save]").click()
        file = tmp_path / "recorded.json"
        saved.value.save_as(file)
        page.locator("#path [data-path=clear]").click()
        page.locator("#path [data-path=file]").set_input_files(str(file))
        page.wait_for_function(f"rcp.path.path.keyframes.length === {len(recorded)}", timeout=WAIT_MS)
        assert keyframes(page) == recorded
        # a chosen size: the list offers the view's, then the usual ones
        options = page.evaluate("[...document.querySelectorAll('#path-size option')].map((o) => o.textContent)")
        assert options == ["the view's (64×48)", "640×360", "1280×720", "1920×1080"]
        page.select_option("#path-size", "640x360")
        page.locator("#path-fps").fill("24")  # frames enough that a poll sees the bar between its ends
        with page.expect_request("**/api/videos") as request:
            page.locator("#path [data-path=render]").click()
        body = request.value.post_data_json
        assert (body["width"], body["height"]) == (640, 360) and body["paint"] == {"iterations": 2}
        link = page.wait_for_selector("#path [data-path=download]:not([hidden])", timeout=120_000)
        frames = int(recorded[-1]["t"] * 24 + 1e-9) + 1
        progress = page.evaluate("rcp.path.progress")
        assert progress[0] == 0 and progress[-1] == frames and progress == sorted(progress)
        assert any(0 < p < frames for p in progress)  # the bar moved while the frames were painted
        with page.expect_download() as video:
            link.click()
        with av.open(io.BytesIO(Path(video.value.path()).read_bytes())) as container:
            decoded = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
        assert len(decoded) == frames and decoded[0].shape == (360, 640, 3)
        context.close()
    assert problems == []


def test_a_360_film_is_saved_as_panoramas_and_rendered(page, tmp_path):
    page.locator("#path [data-path=add]").click()
    page.evaluate(f"rcp.walk.place({json.dumps(SIDE)})")
    page.locator("#path [data-path=add]").click()
    page.select_option("#path-film", "equirect")
    options = page.evaluate("[...document.querySelectorAll('#path-size option')].map((o) => o.value)")
    assert options == ["view", "1024x512", "2048x1024", "3840x1920"]
    with page.expect_download() as saved:
        page.locator("#path [data-path=save]").click()
    file = tmp_path / "pano.json"
    saved.value.save_as(file)
    spec = json.loads(file.read_text())
    assert [(k["projection"], k["stereo"]) for k in spec["keyframes"]] == [("equirect", "mono")] * 2
    # the CLI takes the same file
    from rcp_server.cli import main

    out = tmp_path / "pano.mp4"
    assert (
        main(["render", "sky", "--path", str(file), "--out", str(out), "--fps", "4", "--width", "32", "--height", "16"])
        == 0
    )
    # and the page renders it: a panorama the view's cost (2:1)
    page.locator("#path-fps").fill("4")
    page.locator("#path [data-path=render]").click()
    link = page.wait_for_selector("#path [data-path=download]:not([hidden])", timeout=WAIT_MS)
    with page.expect_download() as video:
        link.click()
    with av.open(io.BytesIO(Path(video.value.path()).read_bytes())) as container:
        decoded = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(decoded) == 5 and decoded[0].shape == (40, 80, 3)


def test_a_render_in_progress_is_cancelled_from_the_page(page):
    button = page.locator("#path [data-path=add]")
    button.click()
    page.evaluate(f"rcp.walk.place({json.dumps(SIDE)})")
    button.click()
    page.fill("#path li[data-index='1'] input", "10")  # a long film: it cannot end before the cancel
    page.dispatch_event("#path li[data-index='1'] input", "change")
    page.select_option("#path-size", "1920x1080")
    page.locator("#path [data-path=render]").click()
    page.wait_for_function("rcp.path.job !== null", timeout=WAIT_MS)
    assert page.evaluate("rcp.path.job.frames") == 24 * 10 + 1
    page.locator("#path [data-path=cancel]").click()
    page.wait_for_function("rcp.path.job === null", timeout=WAIT_MS)
    assert page.text_content("#path [data-path=status]").startswith("cancelled")
    assert page.is_hidden("#path [data-path=download]") and page.is_hidden("#path [data-path=cancel]")
    assert page.is_enabled("#path [data-path=render]")  # another may start
