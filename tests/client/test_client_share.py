"""What a person makes leaves the page, in a real Chromium against a real server: the address carries the view
(scene, camera, painting, per object too) and reopens it with the same picture; bad link values are one notice;
an expired upload's link falls back; a gamepad walks and looks; a phone gets the whole screen and a sheet; a pick
answers on the view and in the Objects section."""

from __future__ import annotations

import json

import numpy as np
from helpers.browser import (
    SIZE,
    WAIT_MS,
    canvas,
    click_view,
    client,
    fresh_page,
    needs_chromium,
    set_slider,
    wait_final,
)
from helpers.servers import BackgroundServer

from rcp_server.painting.picking import object_pixels
from rcp_server.service.walkview import pick_mask

pytestmark = needs_chromium

CAMERA_KEYS = ("eye", "look_at", "up", "fov")


def test_a_link_reopens_the_same_view_and_picture_in_a_fresh_browser(browser, live_server, tmp_path):  # noqa: F811
    with client(browser, live_server.url) as page:
        # walk forward, turn a little, then change settings: a global one, and one for the ground only
        page.keyboard.down("w")
        page.wait_for_timeout(300)  # the key is held this long: that is the input
        page.keyboard.up("w")
        page.keyboard.down("ArrowRight")
        page.wait_for_timeout(150)
        page.keyboard.up("ArrowRight")
        page.wait_for_function("rcp.walk.velocity.every((v) => v === 0)", timeout=WAIT_MS)
        page.select_option("#style", "focus")
        page.click('#paint-mapping [data-value="color"]')
        set_slider(page, "lambda_p", 1)  # the style's 0.3, tripled and more
        click_view(page, SIZE[0] // 2, SIZE[1] - 5)  # the ground
        page.wait_for_function("document.querySelector('#picked').textContent.includes('ground')", timeout=WAIT_MS)
        page.fill("#own-lambda_p", "2")
        page.dispatch_event("#own-lambda_p", "change")
        page.check("#gravity")
        wait_final(page, current=True)
        page.wait_for_function("location.search.includes('objects=')", timeout=WAIT_MS)  # replaceState, throttled
        page.wait_for_timeout(600)  # one more address update at most: the view is at rest
        address = page.url
        assert address == page.evaluate("rcp.shareLink()")
        paint = page.evaluate("rcp.state.paint")
        assert paint == {"style": "focus", "mapping": "color", "lambda_p": 1, "objects": {"ground": {"lambda_p": 2}}}
        camera = page.evaluate("rcp.state.lastCamera")
        assert camera["eye"] != [0.8, 1.7, 38]  # it walked
        picture = canvas(page)
        frame = page.evaluate("rcp.overlay.frame")
        # Copy link puts the same address on the clipboard (or, refused, in a box to copy from)
        page.context.grant_permissions(["clipboard-read", "clipboard-write"])
        page.click("#copy-link")
        page.wait_for_function("document.querySelector('#copy-link').dataset.copied", timeout=WAIT_MS)
        assert page.get_attribute("#copy-link", "data-copied") == address
        assert address in (page.evaluate("navigator.clipboard.readText()"), page.input_value("#link-box"))

    context, other, problems = fresh_page(browser, address)
    try:
        again = wait_final(other)
        assert other.evaluate("rcp.state.scene.name") == "default"
        assert other.evaluate("rcp.state.paint") == paint
        assert {k: other.evaluate("rcp.state.lastCamera")[k] for k in CAMERA_KEYS} == camera
        assert other.evaluate("[rcp.state.gravity, rcp.state.collide]") == [True, True]
        assert other.is_checked("#gravity") and other.input_value("#paint-lambda_p") == "1"
        assert other.input_value("#style") == "focus"
        assert other.locator('[data-override="objects:ground"]').count() == 1
        assert again["paint"] == frame["paint"] and again["spp"] == frame["spp"]
        assert np.array_equal(canvas(other), picture)  # at rest, the same picture
        assert other.evaluate("rcp.state.errors") == []
        other.screenshot(path=str(tmp_path / "link.png"))
    finally:
        context.close()
    assert problems == []


def test_bad_link_values_are_one_notice_and_the_page_works(browser, live_server):  # noqa: F811
    bad = "spp=0&z0=-1&mapping=sideways&eye=1,2&fov=60&objects={oops&colour=3&gravity=maybe&iterations=3"
    url = f"{live_server.url}/?scene=default&width={SIZE[0]}&height={SIZE[1]}&{bad}"
    context, page, problems = fresh_page(browser, url)
    try:
        frame = wait_final(page)
        (notice,) = page.evaluate("rcp.state.errors")
        assert "\n" not in notice and notice.startswith("This link's ")
        for named in (
            "spp must be at least 1",
            "z0 must be more than 0",
            "mapping must be one of",
            "eye must be three numbers",
            "objects must be JSON",
            "'colour' is no setting",
            "gravity must be 0 or 1",
        ):
            assert named in notice, named
        assert page.evaluate("rcp.state.paint") == {"iterations": 3}  # the good one is kept
        assert frame["iteration"] == 3
        scene = page.evaluate("rcp.state.scene.camera")
        assert page.evaluate("rcp.state.lastCamera")["eye"] == scene["eye"]
        assert page.text_content("#toast") == notice
    finally:
        context.close()
    assert problems == []

    # a value the page cannot judge (an object the scene does not have) is the server's one refusal
    url = f"{live_server.url}/?scene=default&width={SIZE[0]}&height={SIZE[1]}&objects=" + json.dumps(
        {"nosuch": {"lambda_p": 0}}
    )
    context, page, problems = fresh_page(browser, url)
    try:
        page.wait_for_function("rcp.state.errors.length > 0", timeout=WAIT_MS)
        wait_final(page)
        (notice,) = page.evaluate("rcp.state.errors")
        assert notice.startswith("Refused: objects: this scene has no 'nosuch'")
        assert page.evaluate("rcp.state.paint") == {}
    finally:
        context.close()
    assert problems == []


def test_an_expired_upload_link_says_so_and_shows_the_default_scene(browser, live_server):  # noqa: F811
    gone = "u-" + "A" * 22
    url = f"{live_server.url}/?scene={gone}&eye=1,2,3&look_at=0,0,0&lambda_p=5&width={SIZE[0]}&height={SIZE[1]}"
    context, page, problems = fresh_page(browser, url)
    try:
        wait_final(page)
        expired = "The uploaded scene of this link has expired; showing the default scene"
        assert page.evaluate("rcp.state.errors") == [expired]
        assert page.evaluate("rcp.state.scene.name") == "default"
        assert page.evaluate("rcp.state.paint") == {}  # the link's settings were for the scene that is gone
        assert page.evaluate("rcp.state.lastCamera.eye") == page.evaluate("rcp.state.scene.camera.eye")
        page.wait_for_function("location.search.startsWith('?scene=default')", timeout=WAIT_MS)
    finally:
        context.close()
    assert problems == ["Failed to load resource: the server responded with a status of 404 (Not Found)"]  # asked


def test_the_token_never_stays_in_the_address(browser):  # noqa: F811
    with BackgroundServer(settle_ms=80, token="sesame") as server:
        context, page, problems = fresh_page(browser, f"{server.url}/?scene=sky&width=64&height=48#token=sesame")
        wait_final(page)
        page.wait_for_function("location.search.includes('eye=')", timeout=WAIT_MS)
        assert "sesame" not in page.url and "#" not in page.url
        assert "sesame" not in page.evaluate("rcp.shareLink()")
        page.reload()  # the tab keeps it
        wait_final(page)
        assert page.evaluate("rcp.state.errors") == []
        context.close()
    assert problems == []


PAD = """() => {
  window.pad = { id: "Test pad (STANDARD GAMEPAD)", index: 0, connected: true, mapping: "standard",
    axes: [0, 0, 0, 0], timestamp: 0,
    buttons: Array.from({ length: 17 }, () => ({ pressed: false, touched: false, value: 0 })) };
  navigator.getGamepads = () => [window.pad, null, null, null];
}"""


def test_a_gamepad_walks_looks_and_resets(browser, live_server):  # noqa: F811
    context, page, problems = fresh_page(browser, f"{live_server.url}/?scene=default&width={SIZE[0]}&height={SIZE[1]}")
    try:
        page.evaluate(PAD)
        wait_final(page)
        page.wait_for_function("!document.querySelector('#o-pad').hidden", timeout=WAIT_MS)
        assert page.text_content("#o-pad").startswith("Test pad")
        start = page.evaluate("rcp.walk.walk")
        # a stick resting inside the dead zone moves nothing
        page.evaluate("pad.axes = [0.05, -0.1, 0.1, 0.05]")
        page.wait_for_timeout(300)
        assert page.evaluate("rcp.walk.walk") == start and page.evaluate("rcp.walk.velocity") == [0, 0, 0]
        # the left stick pushed forward walks forward (level: a walker), and the camera follows
        page.evaluate("pad.axes = [0, -1, 0, 0]")
        page.wait_for_timeout(400)  # held this long: that is the input
        page.evaluate("pad.axes = [0, 0, 0, 0]")
        page.wait_for_function("rcp.walk.velocity.every((v) => v === 0)", timeout=WAIT_MS)
        page.wait_for_function("rcp.collider.flight === null", timeout=WAIT_MS)
        walked = page.evaluate("rcp.walk.walk")
        heading = np.array([np.sin(start["yaw"]), 0, -np.cos(start["yaw"])])
        step = np.subtract(walked["eye"], start["eye"])
        assert step @ heading > 0.5 and abs(step[1]) < 1e-6 and np.linalg.norm(np.cross(step, heading)) < 1e-3
        assert walked["yaw"] == start["yaw"]
        page.wait_for_function(f"rcp.state.lastCamera.eye[2] === {round(walked['eye'][2], 5)}", timeout=WAIT_MS)
        # the right stick looks right; the right trigger goes up
        page.evaluate("pad.axes = [0, 0, 1, 0]; pad.buttons[7].value = 1")
        page.wait_for_timeout(200)
        page.evaluate("pad.axes = [0, 0, 0, 0]; pad.buttons[7].value = 0")
        page.wait_for_function("rcp.walk.velocity.every((v) => v === 0)", timeout=WAIT_MS)
        page.wait_for_function("rcp.collider.flight === null", timeout=WAIT_MS)
        turned = page.evaluate("rcp.walk.walk")
        assert turned["yaw"] > start["yaw"] + 0.05 and turned["eye"][1] > walked["eye"][1]
        # Y resets the camera to the scene's
        page.evaluate("pad.buttons[3].pressed = true")
        page.wait_for_timeout(100)
        page.evaluate("pad.buttons[3].pressed = false")
        assert page.evaluate("rcp.walk.walk.eye") == start["eye"]
    finally:
        context.close()
    assert problems == []


def test_a_phone_gets_the_whole_screen_a_half_sheet_and_touch_to_look_and_walk(browser, live_server, tmp_path):  # noqa: F811
    context = browser.new_context(viewport={"width": 390, "height": 844}, has_touch=True, is_mobile=True)
    page = context.new_page()
    problems: list[str] = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    try:
        page.goto(f"{live_server.url}/?scene=default")
        wait_final(page)
        assert page.evaluate("rcp.state.size") == [390, 844]  # painted at the screen's size
        view = page.locator("#view").bounding_box()
        assert (view["x"], view["y"], view["width"], view["height"]) == (0, 0, 390, 844)
        panel = page.locator("#panel").bounding_box()
        assert panel["height"] < 60 and panel["y"] + panel["height"] == 844  # collapsed to its header, at the bottom
        page.screenshot(path=str(tmp_path / "phone.png"))
        cdp = context.new_cdp_session(page)

        def touch(kind: str, *points) -> None:
            points = [{"x": x, "y": y, "id": k} for k, (x, y) in enumerate(points)]
            cdp.send("Input.dispatchTouchEvent", {"type": kind, "touchPoints": points})

        start = page.evaluate("rcp.state.lastCamera")
        touch("touchStart", (250, 300))
        for x in (230, 210, 190, 170):
            touch("touchMove", (x, 300))
        touch("touchEnd")
        page.wait_for_function("rcp.state.cameraId >= 1", timeout=WAIT_MS)
        looked = page.evaluate("rcp.state.lastCamera")
        f0 = np.subtract(start["look_at"], start["eye"])
        assert looked["eye"] == start["eye"]
        assert np.subtract(looked["look_at"], looked["eye"]) @ np.cross(f0, [0, 1, 0]) > 0  # turned right
        # the on-screen stick, pushed up, walks forward
        stick = page.locator("#stick").bounding_box()
        cx, cy = stick["x"] + stick["width"] / 2, stick["y"] + stick["height"] / 2
        touch("touchStart", (cx, cy))
        touch("touchMove", (cx, cy - 40))
        page.wait_for_timeout(400)  # held: that is the input
        touch("touchEnd")
        settled = "rcp.walk.velocity.every((v) => v === 0) && rcp.collider.flight === null"
        page.wait_for_function(settled, timeout=WAIT_MS)
        walked = page.evaluate("rcp.walk.walk.eye")
        assert np.subtract(walked, looked["eye"]) @ np.subtract(looked["look_at"], looked["eye"]) > 0
        # the panel opens as a sheet over the lower half at most
        page.tap("#panel-toggle")
        page.wait_for_timeout(300)
        panel = page.locator("#panel").bounding_box()
        assert 300 < panel["height"] <= 844 / 2 and panel["width"] == 390
        page.screenshot(path=str(tmp_path / "phone-sheet.png"))
    finally:
        context.close()
    assert problems == []


def test_a_pick_outlines_the_object_and_opens_its_settings_in_view(browser, live_server):  # noqa: F811
    scene = live_server.app.state.service.scenes["figures"]
    names = scene.geometry()[0].object_names
    from rcp_server.painting.loop import paint
    from rcp_server.settings.params import PaintParams

    shows = paint(scene, scene.camera, *SIZE, PaintParams(iterations=1, objects={"houses": {}})).state.object
    rows, columns = np.nonzero(shows.reshape(SIZE[1], SIZE[0]) == names.index("houses"))
    with client(browser, live_server.url, scene="figures") as page:
        section = "document.querySelector('#objects-section').getBoundingClientRect()"
        body = "document.querySelector('#panel-body').getBoundingClientRect()"
        assert page.evaluate(f"{section}.top > {body}.bottom")  # below the fold of the panel at first
        click_view(page, int(columns[len(columns) // 2]), int(rows[len(rows) // 2]))
        page.wait_for_function("rcp.pickMask.shown === 1", timeout=WAIT_MS)
        assert "houses" in page.text_content("#picked")
        assert "shown" in page.get_attribute("#pick", "class")
        # the outline is of the houses, as the server's rays see them
        mask = pick_mask(scene, 0.0, scene.camera, SIZE, "houses")
        assert page.evaluate("[rcp.pickMask.pixels, rcp.canvas.width]")[0] == int(
            object_pixels(scene, 0.0, scene.camera, mask.width, mask.height, "houses").sum()
        )
        assert page.evaluate("[document.querySelector('#pick').width, document.querySelector('#pick').height]") == [
            mask.width,
            mask.height,
        ]
        # the Objects section scrolls into view, the houses selected
        in_view = f"{section}.top >= {body}.top - 1 && {section}.top < {body}.bottom - 100"
        page.wait_for_function(in_view, timeout=WAIT_MS)
        assert page.get_attribute('#own-target [data-per="objects"]', "aria-pressed") == "true"
        # its choices are wide enough to read: "normal", not "norma"
        wide = page.evaluate("""() => { const select = document.querySelector('#own-mapping');
            const text = document.createElement('canvas').getContext('2d');
            text.font = getComputedStyle(select).font;
            const widest = Math.max(...[...select.options].map((o) => text.measureText(o.text).width));
            return [select.getBoundingClientRect().width, widest]; }""")
        assert wide[0] >= wide[1] + 24  # the text, and the arrow beside it
        page.wait_for_function("!document.querySelector('#pick').classList.contains('shown')", timeout=WAIT_MS)
