"""The browser client in a real headless Chromium against a real server on loopback.

Each test opens the client with a small painting (480x270), mostly on the default scene, and waits on
conditions, never on fixed sleeps, except where holding a key *is* the input. Frames painted at
rest are deterministic (seeded, same camera and settings give the same JPEG), so "the view came back"
is checked as pixel equality.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from helpers.browser import (
    SIZE,
    WAIT_MS,
    canvas,
    click_view,
    client,
    difference,
    needs_chromium,
    sent,
    set_slider,
    wait_final,
)
from helpers.servers import BackgroundServer

from rcp_server.painting.loop import paint
from rcp_server.service import protocol
from rcp_server.settings.params import PaintParams

pytestmark = needs_chromium


@pytest.fixture
def page(browser, live_server):
    with client(browser, live_server.url) as page:
        yield page


# ---- tests ----


def test_page_streams_refined_frames_into_the_canvas(page):
    hello, *rest = sent(page)
    assert hello == {"type": "hello", "scene": "default", "width": SIZE[0], "height": SIZE[1], "quality": 80}
    # and the walker's first (still) move, which measures its body for the collisions
    assert rest == [{"type": "move", "id": 1, "eye": [0.8, 1.7, 38], "delta": [0, 0, 0], "height": None}]
    assert page.evaluate("[rcp.canvas.width, rcp.canvas.height]") == list(SIZE)
    image = canvas(page)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    assert image.std() > 20 and len(np.unique(image.reshape(-1, 3), axis=0)) > 1000  # a picture, not a fill
    assert page.text_content("#o-connection") == "connected"
    # the overlay refreshes a few times a second: wait for it to show the refined frame
    page.wait_for_function("document.getElementById('o-phase').textContent === 'refined'", timeout=WAIT_MS)
    assert int(page.text_content("#o-frames")) >= 2  # a quick walk frame, then refinements
    assert page.text_content("#o-size") == f"{SIZE[0]}×{SIZE[1]}"
    assert page.text_content("#o-scale") == "full"
    # the panel shows the scene's painting defaults (scenes/default.toml: lambda_p 12, 6 iterations)
    assert page.input_value("#paint-lambda_p") == "12"
    assert page.input_value("#paint-iterations") == "6"
    assert page.get_attribute('#paint-mapping [data-value="color"]', "aria-pressed") == "true"
    # the walk camera (yaw, pitch) derived from the scene's camera gives back the scene's camera
    scene, walk = page.evaluate("[rcp.state.scene.camera, rcp.state.lastCamera]")
    for key in ("eye", "look_at", "up"):
        assert np.allclose(walk[key], scene[key], atol=1e-4), key
    assert walk["fov"] == scene["fov"]


def test_holding_w_walks_forward_and_the_view_follows(page):
    before = canvas(page)
    start = page.evaluate("rcp.state.lastCamera")
    page.keyboard.down("w")
    page.wait_for_timeout(300)  # the key is held this long: that is the input
    page.keyboard.up("w")
    # at rest: the keys' velocity gone, and no collision move in flight or left to send (its answer moves the eye)
    page.wait_for_function(
        "rcp.walk.velocity.every((v) => v === 0) && rcp.collider.flight === null"
        " && rcp.collider.pending.every((x) => x === 0)",
        timeout=WAIT_MS,
    )
    wait_final(page, current=True)
    last_id = page.evaluate("rcp.state.cameraId")

    cameras = sent(page, "camera")
    assert len(cameras) >= 3  # one per animation frame while moving, never more
    assert [c["id"] for c in cameras] == list(range(1, last_id + 1))
    offset = np.subtract(start["look_at"], start["eye"])
    f0 = offset / np.linalg.norm(offset)
    for previous, camera in zip([start, *cameras], cameras, strict=False):
        step = np.subtract(camera["eye"], previous["eye"])
        assert np.linalg.norm(step) > 0  # only changed cameras are sent
        assert step @ f0 > 0.999 * np.linalg.norm(step)  # straight ahead
        assert np.allclose(np.subtract(camera["look_at"], camera["eye"]), offset, atol=1e-3)  # no turning
        assert camera["up"] == [0, 1, 0] and camera["fov"] == start["fov"]
    walked = np.subtract(cameras[-1]["eye"], start["eye"]) @ f0
    assert 0.3 < walked < 10  # about 0.3 s at the scene's walking speed (eased)
    assert difference(canvas(page), before) > 3
    page.wait_for_function("document.getElementById('o-latency').textContent.endsWith(' ms')", timeout=WAIT_MS)

    # dragging the mouse to the right turns the view to the right, at the same height
    page.mouse.move(200, 300)
    page.mouse.down()
    page.mouse.move(260, 300, steps=4)
    page.mouse.up()
    page.wait_for_function(f"rcp.state.cameraId > {last_id}", timeout=WAIT_MS)
    turned = sent(page, "camera")[-1]
    f1 = np.subtract(turned["look_at"], turned["eye"]) / np.linalg.norm(offset)
    right = np.cross(f0, [0, 1, 0])
    assert f1 @ right > 0.05 and abs(f1[1] - f0[1]) < 1e-4
    assert turned["eye"] == cameras[-1]["eye"]


def test_one_finger_looks_and_two_fingers_walk(browser, live_server):
    with client(browser, live_server.url, touch=True) as page:
        cdp = page.context.new_cdp_session(page)

        def touch(kind: str, *points) -> None:
            points = [{"x": x, "y": y, "id": k} for k, (x, y) in enumerate(points)]
            cdp.send("Input.dispatchTouchEvent", {"type": kind, "touchPoints": points})

        start = page.evaluate("rcp.state.lastCamera")
        offset = np.subtract(start["look_at"], start["eye"])
        f0 = offset / np.linalg.norm(offset)
        # one finger drags the world to the left: the view turns right
        touch("touchStart", (300, 300))
        for x in (280, 260, 240):
            touch("touchMove", (x, 300))
        touch("touchEnd")
        page.wait_for_function("rcp.state.cameraId >= 1", timeout=WAIT_MS)
        looked = sent(page, "camera")[-1]
        assert looked["eye"] == start["eye"]
        assert np.subtract(looked["look_at"], looked["eye"]) @ np.cross(f0, [0, 1, 0]) > 0
        # two fingers pushed up the screen: the camera walks forward, the view stays
        count = len(sent(page, "camera"))
        touch("touchStart", (250, 400), (350, 400))
        for y in (380, 360, 340, 320):
            touch("touchMove", (250, y), (350, y))
        touch("touchEnd")
        page.wait_for_function(f"rcp.sent.filter((m) => m.type === 'camera').length > {count}", timeout=WAIT_MS)
        walked = sent(page, "camera")[-1]
        f1 = np.subtract(looked["look_at"], looked["eye"])
        step = np.subtract(walked["eye"], looked["eye"])
        assert step @ f1 > 0.999 * np.linalg.norm(step) * np.linalg.norm(f1) and np.linalg.norm(step) > 0.1
        assert np.allclose(np.subtract(walked["look_at"], walked["eye"]), f1, atol=1e-3)


def test_a_slider_repaints_and_its_reset_restores_the_painting(page):
    before, seq = canvas(page), page.evaluate("rcp.overlay.frame.seq")
    set_slider(page, "lambda_p", 40)
    page.wait_for_function("rcp.sent.some((m) => m.type === 'paint')", timeout=WAIT_MS)
    assert sent(page, "paint") == [{"type": "paint", "lambda_p": 40}]
    assert "changed" in page.get_attribute('[data-field="lambda_p"]', "class")
    seq = wait_final(page, after_seq=seq)["seq"]
    assert difference(canvas(page), before) > 2

    # a value outside the server's range is refused in the panel and never sent
    page.fill("#paint-iterations", "999")
    page.press("#paint-iterations", "Enter")
    assert "invalid" in page.get_attribute("#paint-iterations", "class")

    page.click('[data-field="lambda_p"] .reset')
    page.wait_for_function("rcp.sent.filter((m) => m.type === 'paint').length === 2", timeout=WAIT_MS)
    assert sent(page, "paint")[-1] == {"type": "paint", "lambda_p": None}
    assert page.input_value("#paint-lambda_p") == "12"
    wait_final(page, after_seq=seq)
    assert np.array_equal(canvas(page), before)  # the scene's painting again, exactly


def test_save_downloads_the_view_as_a_full_size_png(page):
    with page.expect_request("**/api/render") as request, page.expect_download(timeout=WAIT_MS) as download:
        page.click("#save")
    body = request.value.post_data_json
    protocol.RenderRequest.model_validate(body)
    assert body["scene"] == "default" and body["format"] == "png"
    assert (body["width"], body["height"]) == SIZE
    assert body["camera"] == page.evaluate("rcp.state.lastCamera")
    assert body["paint"]["spp"] >= 4  # at least the samples of the refined view
    assert download.value.suggested_filename.startswith("rcp-default-")
    data = Path(download.value.path()).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert struct.unpack(">II", data[16:24]) == SIZE  # IHDR: width, height
    assert page.text_content("#save") == "Save PNG"


def test_a_dropped_connection_comes_back_with_the_same_view(page):
    set_slider(page, "lambda_p", 30)
    page.click("#view", position={"x": 100, "y": 300})  # back to the view: arrows turn the camera again
    page.keyboard.down("ArrowLeft")
    page.wait_for_timeout(200)  # the key is held this long: that is the input
    page.keyboard.up("ArrowLeft")
    camera_id = page.evaluate("rcp.state.cameraId")
    assert camera_id > 0
    wait_final(page, camera_id=camera_id)
    before, camera = canvas(page), page.evaluate("rcp.state.lastCamera")
    hellos, frames = len(sent(page)), page.evaluate("rcp.overlay.frames")

    page.evaluate("rcp.connection.socket.close()")  # the socket drops under the client
    page.wait_for_function("rcp.connection.opens === 2 && rcp.state.readies === 2", timeout=WAIT_MS)
    assert page.text_content("#o-connection") in ("connected", "connecting…")
    restored = sent(page)[hellos:]
    assert restored[0]["type"] == "hello" and restored[0]["scene"] == "default"
    cameras = [m for m in restored if m["type"] == "camera"]
    assert [(c["eye"], c["look_at"]) for c in cameras] == [(camera["eye"], camera["look_at"])]
    assert {"type": "paint", "lambda_p": 30} in restored

    wait_final(page, camera_id=cameras[0]["id"])
    assert page.evaluate("rcp.overlay.frames") > frames
    assert np.array_equal(canvas(page), before)  # the same painting as before the drop


def test_every_message_the_client_sends_is_in_the_protocol(page):
    schema = page.evaluate("rcp.PROTOCOL")
    every = protocol.schemas()  # protocol.js writes the camera and paint schemas once; the browser sees them whole
    assert schema == {"client": every["client"], "paint": every["paint"], "camera": every["camera"]}
    # the panel has a control for every painting field, and no other (the style has its own picker)
    # (the style has its own picker, the settings per object and material their section)
    own = {"type", "style", "objects", "materials"}
    assert sorted(page.evaluate("rcp.panel.fields")) == sorted(set(schema["paint"]["properties"]) - own)
    # engine defaults the panel shows for fields a scene leaves out are the engine's
    assert page.evaluate("rcp.ENGINE_DEFAULTS") == PaintParams().settings()
    click_view(page, SIZE[0] // 2, SIZE[1] - 5)  # a pick: what the view shows there
    page.wait_for_function("document.querySelector('#picked').textContent.includes('ground')", timeout=WAIT_MS)

    # use every control that sends something
    page.click('#paint-mapping [data-value="depth"]')
    set_slider(page, "iterations", 3)
    # a combination the server refuses (the image method cannot move eyes) is undone in the panel
    set_slider(page, "lambda_e", 0.5)
    page.wait_for_function("rcp.sent.some((m) => m.type === 'paint' && m.lambda_e === 0.5)", timeout=WAIT_MS)
    page.click('#paint-method [data-value="image"]')
    page.wait_for_function("rcp.state.errors.length === 1", timeout=WAIT_MS)
    assert page.get_attribute('#paint-method [data-value="raytrace"]', "aria-pressed") == "true"
    assert "method" not in page.evaluate("rcp.state.paint")
    page.click("#reset-paint")
    page.check("#temporal")
    page.locator("#quality").fill("60")
    page.select_option("#resolution", "0.5")
    page.select_option("#scene", "sea")
    page.wait_for_function("rcp.state.scene && rcp.state.scene.name === 'sea'", timeout=WAIT_MS)
    page.check("#animate")
    page.keyboard.down("d")
    page.wait_for_timeout(100)
    page.keyboard.up("d")
    page.mouse.move(100, 150)
    page.mouse.wheel(0, 200)
    page.wait_for_function("rcp.sent.filter((m) => m.type === 'camera').length >= 2", timeout=WAIT_MS)

    messages = sent(page)
    assert {m["type"] for m in messages} == set(page.evaluate("Object.keys(rcp.MESSAGES)")) <= set(schema["client"])
    for message in messages:
        assert set(message) <= set(schema["client"][message["type"]]["properties"]), message
        protocol.client_message.validate_python(message)  # the server's own models take it
    paints = [m for m in messages if m["type"] == "paint"]
    assert any(m.get("mapping") == "depth" for m in paints) and any(m.get("iterations") == 3 for m in paints)
    assert paints[-1] == {"type": "paint", "mapping": None, "iterations": None, "lambda_e": None}
    assert {"type": "view", "width": SIZE[0] // 2, "height": SIZE[1] // 2, "quality": 60} in messages
    assert {"type": "mode", "animate": True} in messages
    errors = page.evaluate("rcp.state.errors")
    assert len(errors) == 1, errors  # the server accepted every other one
    (refusal,) = errors
    assert refusal.startswith("Refused: ") and "lambda_e" in refusal


def test_a_click_picks_an_object_and_the_section_gives_it_settings_of_its_own(browser, live_server):
    scene = live_server.app.state.service.scenes["figures"]
    names = scene.geometry()[0].object_names
    shows = paint(scene, scene.camera, *SIZE, PaintParams(iterations=1, objects={"houses": {}})).state.object
    rows, columns = np.nonzero(shows.reshape(SIZE[1], SIZE[0]) == names.index("houses"))
    with client(browser, live_server.url, scene="figures") as page:
        before = canvas(page)
        click_view(page, int(columns[len(columns) // 2]), int(rows[len(rows) // 2]))
        page.wait_for_function("document.querySelector('#picked').textContent.includes('houses')", timeout=WAIT_MS)
        assert "material plaster" in page.text_content("#picked")
        seq = page.evaluate("rcp.overlay.frame.seq")
        page.fill("#own-lambda_p", "0")
        page.dispatch_event("#own-lambda_p", "change")
        page.wait_for_function(
            "rcp.sent.some((m) => m.type === 'paint' && m.objects && m.objects.houses.lambda_p === 0)", timeout=WAIT_MS
        )
        assert page.locator('[data-override="objects:houses"]').count() == 1
        assert page.locator('[data-scene-override="objects:figure"]').count() == 1  # the scene's own, listed
        frame = wait_final(page, seq)
        assert frame["paint"]["objects"]["houses"] == {"lambda_p": 0}
        assert frame["paint"]["objects"]["figure"] == {"lambda_p": 0}  # the scene's own stays, merged
        still = canvas(page)
        assert difference(still, before) > 0.1  # the houses no longer smudge
        # the houses as the engine paints them with that setting, not as without it (up to the JPEG's error)
        houses = (shows == names.index("houses")).reshape(SIZE[1], SIZE[0])

        def engine(settings):
            image = paint(scene, scene.camera, *SIZE, scene.painting({**settings, "spp": frame["spp"]})).image
            return (image[houses] * 255).round().astype(np.uint8)

        with_it = difference(still[houses], engine({"objects": {"houses": {"lambda_p": 0}}}))
        assert with_it < 4 and with_it < difference(still[houses], engine({})) / 2
        seq = frame["seq"]
        page.click('[data-override="objects:houses"] button')
        page.wait_for_function("rcp.sent.some((m) => m.type === 'paint' && m.objects === null)", timeout=WAIT_MS)
        assert page.locator("[data-override]").count() == 0
        assert "houses" not in wait_final(page, seq)["paint"]["objects"]


def test_a_busy_server_is_tried_again_after_the_time_it_states(browser):
    with (
        BackgroundServer(settle_ms=80, max_sessions=1, walk_retry_s=1) as server,
        client(browser, server.url, "sky") as first,
    ):
        with client(browser, server.url, "sky", wait=False) as second:
            # the server refuses the second walk-through in one line and closes it at once (1013, its time stated):
            # the page holds that long, then offers to try again
            second.wait_for_function("rcp.connection.state === 'offered'", timeout=WAIT_MS)
            assert "limit of 1 walk-throughs; try again in 1 s" in second.evaluate("rcp.state.errors")[0]
            assert second.evaluate("rcp.overlay.frames") == 0 and second.is_visible("#o-retry")
            first.close()  # the first walk-through ends: trying again gets in
            second.click("#o-retry")
            wait_final(second)
            assert second.text_content("#o-connection") == "connected"
            assert second.evaluate("rcp.connection.opens") >= 2 and second.evaluate("rcp.state.readies") == 1


def test_a_server_with_a_token_walks_and_saves_for_the_page_that_has_it(browser):
    with BackgroundServer(settle_ms=80, token="sesame") as server:
        with client(browser, server.url, "sky", fragment="#token=sesame") as page:
            with page.expect_request("**/api/render") as request, page.expect_download(timeout=WAIT_MS) as download:
                page.click("#save")
            assert request.value.headers["authorization"] == "Bearer sesame"
            assert Path(download.value.path()).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        # without it the page says what is missing and stops asking
        context = browser.new_context()
        page = context.new_page()
        page.goto(f"{server.url}/?scene=sky")
        page.wait_for_function("rcp.state.errors.length > 0", timeout=WAIT_MS)
        assert "needs a token" in page.evaluate("rcp.state.errors")[0]
        assert page.text_content("#o-connection").startswith("needs a token")
        assert page.evaluate("rcp.overlay.frames") == 0
        context.close()
