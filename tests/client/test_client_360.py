"""The client's 360° view in a real headless Chromium (WebGL2 through SwiftShader) against a real server: it
asks for equirect paintings of the walk's position, draws the newest around the viewer, looks around with no
message to the server, and walks by asking for new panoramas.

What the view draws is checked pixel by pixel against this file's own resampling of the panorama (the
directions of shared/MISSION.md's equirect convention), so a flipped, mirrored or turned sphere fails.
"""

from __future__ import annotations

import io

import av
import httpx
import numpy as np
import pytest
from helpers.browser import SIZE, WAIT_360_MS, client_360, data_url_image, needs_chromium
from PIL import Image

pytestmark = needs_chromium

# a panorama whose every pixel's color is its own direction, (d + 1) / 2 in the panorama's frame
DIRECTIONS = """async ([w, h]) => {
  const data = new ImageData(w, h);
  for (let j = 0; j < h; j++) for (let i = 0; i < w; i++) {
    const phi = (2 * (i + 0.5) / w - 1) * Math.PI, theta = (1 - 2 * (j + 0.5) / h) * Math.PI / 2;
    const d = [Math.cos(theta) * Math.sin(phi), Math.sin(theta), Math.cos(theta) * Math.cos(phi)];
    for (let c = 0; c < 3; c++) data.data[4 * (j * w + i) + c] = Math.round((d[c] + 1) * 127.5);
    data.data[4 * (j * w + i) + 3] = 255;
  }
  rcp.view360.pano.show(await createImageBitmap(data), "mono");
}"""


# two seconds of turning a little on every animation frame: the frames drawn a second, and the browser's
TURNING = """() => new Promise((done) => {
  const drawn = rcp.view360.pano.drawn, start = performance.now();
  let frames = 0;
  function turn(now) {
    frames += 1;
    rcp.walk.look(2, 0);
    if (now - start < 2000) requestAnimationFrame(turn);
    else done([(rcp.view360.pano.drawn - drawn) * 1000 / (now - start), frames * 1000 / (now - start)]);
  }
  requestAnimationFrame(turn);
})"""


@pytest.fixture
def page(webgl_browser, live_server):
    with client_360(webgl_browser, live_server.url) as page:
        yield page


# ---- helpers ----


def drawn(page) -> np.ndarray:
    """What the 360° view draws now."""
    return data_url_image(page.evaluate("rcp.view360.snapshot(rcp.walk.walk, rcp.state.size[1])"))


def view_of(page) -> dict:
    return page.evaluate(
        """({ yaw: rcp.walk.walk.yaw, pitch: rcp.walk.walk.pitch, fov: rcp.walk.walk.fov,
              yaw0: rcp.view360.yaw0, size: [rcp.view360.canvas.width, rcp.view360.canvas.height] })"""
    )


def directions(view: dict) -> np.ndarray:
    """Each screen pixel's view direction in the panorama's frame (x right, y up, z forward): (h, w, 3).
    The walk's convention (client/camera.js): yaw 0 looks down -z, positive yaw turns right."""

    def forward(yaw, pitch):
        return np.array([np.sin(yaw) * np.cos(pitch), np.sin(pitch), -np.cos(yaw) * np.cos(pitch)])

    def right(yaw):
        return np.array([np.cos(yaw), 0.0, np.sin(yaw)])

    w, h = view["size"]
    f, r = forward(view["yaw"], view["pitch"]), right(view["yaw"])
    u = np.cross(r, f)
    tan = np.tan(np.radians(view["fov"]) / 2)
    x = ((np.arange(w) + 0.5) / w * 2 - 1) * tan * w / h
    y = (1 - (np.arange(h) + 0.5) / h * 2) * tan
    d = f + x[None, :, None] * r + y[:, None, None] * u
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    r0, f0 = right(view["yaw0"]), forward(view["yaw0"], 0.0)
    return np.stack([d @ r0, d[..., 1], d @ f0], axis=-1)


def resampled(panorama: np.ndarray, view: dict) -> np.ndarray:
    """The view of an equirect ``panorama`` (H, 2H, 3): longitude phi = (2s - 1) pi, latitude
    theta = (1 - 2t) pi / 2; bilinear, the longitude wrapping."""
    d = directions(view)
    rows, cols = panorama.shape[:2]
    s = np.arctan2(d[..., 0], d[..., 2]) / (2 * np.pi) + 0.5
    t = 0.5 - np.arcsin(np.clip(d[..., 1], -1, 1)) / np.pi
    x, y = s * cols - 0.5, np.clip(t * rows - 0.5, 0, rows - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    y1 = np.minimum(y0 + 1, rows - 1)
    x0, x1 = x0 % cols, (x0 + 1) % cols
    top = panorama[y0, x0] * (1 - fx) + panorama[y0, x1] * fx
    bottom = panorama[y1, x0] * (1 - fx) + panorama[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def turn(page, dyaw: float, pitch: float) -> None:
    page.evaluate(f"rcp.walk.walk = {{ ...rcp.walk.walk, yaw: rcp.view360.yaw0 + {dyaw}, pitch: {pitch} }}")


def enter_360(page) -> dict:
    """Turn the 360° view on and wait for its first refined panorama; that frame's description."""
    seq = page.evaluate("rcp.overlay.frame.seq")
    page.click("#view360")
    page.wait_for_function(
        """(seq) => { const f = rcp.overlay.frame;
            return f.final && f.seq > seq && rcp.view360.accepts(f) && rcp.view360.pano.uploaded > 0; }""",
        arg=seq,
        timeout=WAIT_360_MS,
    )
    return page.evaluate("rcp.overlay.frame")


# ---- tests ----


def test_the_view_is_the_panorama_seen_from_inside_in_every_direction(page):
    """The renderer alone, on a panorama of directions: every screen pixel shows its own direction."""
    assert page.evaluate("rcp.view360.available()")
    page.click("#view360")
    page.evaluate("rcp.connection.stop()")  # nothing from the server replaces the panorama below
    page.evaluate(DIRECTIONS, [1024, 512])
    for dyaw, pitch in [(0, 0), (2.5, 0.6), (-1.2, -1.3), (np.pi, 0.1)]:  # pi: across the longitude's seam
        turn(page, dyaw, pitch)
        view = view_of(page)
        expected = (directions(view) + 1) * 127.5
        error = np.abs(drawn(page) - expected)
        assert error.max() <= 2.0, (dyaw, pitch, error.max())  # half a texel's slope, and the rounding


def test_the_360_view_asks_for_the_panorama_of_the_walks_position_and_draws_it(page, live_server):
    flat_camera = page.evaluate("rcp.state.lastCamera")
    frame = enter_360(page)
    width, height = frame["width"], frame["height"]
    assert width == 2 * height
    view, camera = [m for m in page.evaluate("rcp.sent") if m["type"] in ("view", "camera")][-2:]
    assert (view["type"], view["width"], view["height"]) == ("view", width, height)  # the size first
    assert camera["projection"] == "equirect" and camera["stereo"] == "mono"
    assert camera["eye"] == flat_camera["eye"] and camera["look_at"][1] == camera["eye"][1]  # level
    assert frame["camera_id"] == camera["id"]
    # the panorama drawn is the server's painting of that camera, seen through the walk's view
    body = {"scene": "default", "width": width, "height": height, "format": "png", "camera": camera}
    body["camera"] = {k: v for k, v in camera.items() if k not in ("type", "id")}
    body["paint"] = {"spp": frame["spp"]}
    response = httpx.post(f"{live_server.url}/api/render", json=body, timeout=120)
    assert response.status_code == 200, response.text
    panorama = np.asarray(Image.open(io.BytesIO(response.content)).convert("RGB")).astype(np.float64)
    for dyaw, pitch in [(0, 0), (2.2, 0.3), (-0.8, -0.5)]:
        turn(page, dyaw, pitch)
        view = view_of(page)
        shown = drawn(page)
        right = np.abs(shown - resampled(panorama, view)).mean()
        turned = np.abs(shown - resampled(panorama, {**view, "yaw0": view["yaw0"] + np.pi / 2})).mean()
        mirrored = np.abs(shown - resampled(panorama[:, ::-1], view)).mean()
        assert right < 8, (dyaw, pitch, right)  # the stream's JPEG (3 to 6 levels here), the resampling
        assert right * 3 < min(turned, mirrored), (right, turned, mirrored)


def test_dragging_looks_around_with_no_message_and_walking_repaints(page):
    enter_360(page)
    page.wait_for_timeout(300)  # the last refinement's messages are all sent
    before = drawn(page)
    sent, counted, frames = (
        len(page.ws_sent),
        page.evaluate("rcp.state.messages"),
        page.evaluate("rcp.view360.pano.drawn"),
    )
    yaw = page.evaluate("rcp.walk.walk.yaw")
    # the browser's own animation frames, counted over the drag: the display's rate, here
    page.evaluate("window.frameCount = 0; (function count() { frameCount++; requestAnimationFrame(count); })()")
    started = page.evaluate("performance.now()")
    page.mouse.move(200, 300)
    page.mouse.down()
    for k in range(1, 61):  # a second's drag, a move every 16 ms as a mouse sends them
        page.mouse.move(200 + 4 * k, 300 - k)
        page.wait_for_timeout(16)
    page.mouse.up()
    seconds = (page.evaluate("performance.now()") - started) / 1000
    drawn_while = page.evaluate("rcp.view360.pano.drawn") - frames
    messages, display = len(page.ws_sent) - sent, page.evaluate("frameCount") / seconds
    print(
        f"\n360° view, dragging for {seconds:.1f} s: {drawn_while / seconds:.1f} frames drawn a second, the browser's "
        f"animation frames {display:.1f} a second, {messages} messages sent"
    )
    page.wait_for_timeout(100)  # an animation frame to draw the last move
    assert page.evaluate("rcp.walk.walk.yaw") > yaw  # dragged right: turned right
    assert drawn_while >= 5  # drawn as the drag went, not once at its end
    assert np.abs(drawn(page) - before).mean() > 10  # another part of the sphere
    assert len(page.ws_sent) == sent  # the browser sent nothing on the socket
    assert page.evaluate("rcp.state.messages") == counted
    # the mouse moved about 20 times a second above (Playwright's round trips); turned on every animation
    # frame instead, as a fast mouse does, the view is drawn on every one the browser gives, and still
    # nothing is sent
    drawn_each, shown_each = page.evaluate(TURNING)
    print(f"turning on every animation frame: {drawn_each:.1f} frames drawn a second of {shown_each:.1f}")
    assert len(page.ws_sent) == sent
    # the overlay says how often the view is drawn here (a person can read the figure too)
    page.wait_for_function("/^360° · [1-9][0-9]* a second$/.test(document.getElementById('o-view').textContent)")
    assert page.is_visible("#o-view")
    # walking moves the eye: new panorama cameras, each level, and a refined panorama of the last one
    eye = page.evaluate("rcp.state.lastCamera.eye")
    page.keyboard.down("w")
    page.wait_for_timeout(300)  # the key is held this long: that is the input
    page.keyboard.up("w")
    # eased to a stop, and no collision move in flight or left to send: the last camera sent
    page.wait_for_function(
        "rcp.walk.velocity.every((v) => v === 0) && rcp.collider.flight === null"
        " && rcp.collider.pending.every((x) => x === 0)"
    )
    page.wait_for_timeout(100)
    cameras = [m for m in page.evaluate("rcp.sent") if m["type"] == "camera"]
    last = cameras[-1]
    assert last["eye"] != eye and last["projection"] == "equirect"
    assert last["look_at"][1] == last["eye"][1]
    page.wait_for_function(
        "(id) => rcp.overlay.frame.final && rcp.overlay.frame.camera_id === id", arg=last["id"], timeout=WAIT_360_MS
    )
    # and back to the flat view: its camera first, then its size
    page.click("#view360")
    camera, view = [m for m in page.evaluate("rcp.sent") if m["type"] in ("view", "camera")][-2:]
    assert camera.get("projection", "perspective") == "perspective"  # the field's default
    assert (camera["type"], view["type"], view["width"], view["height"]) == ("camera", "view", *SIZE)
    assert page.evaluate("rcp.view360.canvas.hidden")


def test_a_path_taken_in_the_360_view_renders_a_360_video(webgl_browser, live_server, tmp_path):
    with client_360(webgl_browser, live_server.url, scene="sky") as page:
        enter_360(page)
        add = page.locator("#path [data-path=add]")
        add.click()
        page.evaluate("rcp.walk.walk = { ...rcp.walk.walk, eye: rcp.walk.walk.eye.map((x) => x + 1) }")
        add.click()
        keyframes = page.evaluate("rcp.path.path.keyframes")
        assert [(k["projection"], k["stereo"]) for k in keyframes] == [("equirect", "mono")] * 2
        page.locator("#path-fps").fill("2")
        page.locator("#path [data-path=render]").click()
        link = page.wait_for_selector("#path [data-path=download]:not([hidden])", timeout=WAIT_360_MS)
        with page.expect_download() as video:
            link.click()
        out = tmp_path / "360.mp4"
        video.value.save_as(out)
    with av.open(str(out)) as container:
        frames = list(container.decode(video=0))
        found = {sd.type.name for sd in frames[0].side_data}
    assert len(frames) == 3 and frames[0].width == 2 * frames[0].height  # the panorama's size, as the view asked
    assert {"SPHERICAL", "STEREO3D"} <= found  # FFmpeg's reader sees a 360° video
