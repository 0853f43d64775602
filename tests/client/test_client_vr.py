"""VR in a real headless Chromium against a real server, the headset emulated in the page by Meta's WebXR
runtime ``iwer`` (a Quest 3): entering VR draws both eyes from a stereo top-bottom panorama, a head turn
changes the view with no message to the server, and the thumbstick walks by sending cameras.

``iwer`` comes from the npm registry at a pinned version, once per machine, into a cache directory (npm is
on every machine of this project's kind); the test hands it to the page with ``add_init_script``, never
through the product's client.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from helpers.browser import client_360, data_url_image, needs_chromium
from helpers.npm import npm_package

IWER_VERSION = "2.5.0"
HEADSET = """
window.xrDevice = new IWER.XRDevice(IWER.metaQuest3);
xrDevice.installRuntime({ forceInstall: true }); // over Chromium's own navigator.xr, which has no headset
xrDevice.stereoEnabled = true; // two eyes, each its half of the layer
"""

# the headset's frames drawn a second, over a second of the head turning a little in every one
XR_RATE = """() => new Promise((done) => {
  const frames = rcp.vr.frames, start = performance.now();
  let yaw = 1.2;
  const timer = setInterval(() => {
    yaw += 0.01;
    xrDevice.quaternion.set(0, Math.sin(yaw / 2), 0, Math.cos(yaw / 2));
    const seconds = (performance.now() - start) / 1000;
    if (seconds >= 1) { clearInterval(timer); done((rcp.vr.frames - frames) / seconds); }
  }, 8);
})"""

pytestmark = needs_chromium


@pytest.fixture(scope="session")
def iwer() -> str:
    """The source of ``iwer``'s browser bundle (its UMD build: defines window.IWER)."""
    return (npm_package("iwer", IWER_VERSION) / "iwer" / "build" / "iwer.min.js").read_text()


def shot(page) -> np.ndarray:
    """What the next headset frame draws (both eyes, side by side)."""
    page.evaluate("rcp.vr.shot = null; rcp.vr.capture = true")
    page.wait_for_function("rcp.vr.shot !== null", timeout=10_000)
    return data_url_image(page.evaluate("rcp.vr.shot"))


def head_turned(page, yaw: float) -> None:
    """The emulated head turned ``yaw`` radians to the left (about +y), level."""
    page.evaluate(f"xrDevice.quaternion.set(0, {math.sin(yaw / 2)}, 0, {math.cos(yaw / 2)})")


def test_enter_vr_is_offered_only_where_a_headset_is(webgl_browser, live_server):
    with client_360(webgl_browser, live_server.url, scene="sky") as page:
        page.wait_for_timeout(500)  # isSessionSupported has answered
        assert page.is_hidden("#enter-vr")  # Chromium's own navigator.xr: no immersive-vr here


def test_vr_shows_each_eye_its_half_turns_with_the_head_and_walks_with_the_thumbstick(
    webgl_browser,
    live_server,
    iwer,
):
    with client_360(webgl_browser, live_server.url, init_script=iwer + HEADSET) as page:
        page.click("#enter-vr")  # a click: the session needs a user gesture
        page.wait_for_function("rcp.vr.frames > 2", timeout=30_000)
        assert page.text_content("#enter-vr") == "Exit VR"
        # the client asks for stereo top-bottom panoramas and draws them, each eye in its half of the layer
        camera = [m for m in page.evaluate("rcp.sent") if m["type"] == "camera"][-1]
        assert (camera["projection"], camera["stereo"], camera["eyes"]) == ("equirect", "top-bottom", "shared")
        page.wait_for_function(
            """(id) => { const f = rcp.overlay.frame; return f.final && f.camera_id === id
                && rcp.view360.pano.layout.stereo === 'top-bottom'; }""",
            arg=camera["id"],
            timeout=60_000,
        )
        frame = page.evaluate("rcp.overlay.frame")
        assert frame["width"] == frame["height"]  # 2H x H an eye, one eye above the other
        views = page.evaluate("rcp.vr.views")
        assert [v["eye"] for v in views] == ["left", "right"]
        (lx, ly, lw, lh), (rx, ry, rw, rh) = views[0]["viewport"], views[1]["viewport"]
        assert lw > 0 and (rx, ry, rw, rh) == (lx + lw, ly, lw, lh)  # side by side, the same size
        ahead = shot(page)
        left, right = ahead[:, : ahead.shape[1] // 2], ahead[:, ahead.shape[1] // 2 :]
        assert left.std() > 10 and right.std() > 10  # both eyes see the village
        assert 0 < np.abs(left - right).mean() < 30  # two eyes apart: alike, not the same image
        # a head turn: another view, drawn from the panorama here, with nothing sent to the server
        page.wait_for_timeout(300)  # the last refinement's messages are all sent
        sent, counted = len(page.ws_sent), page.evaluate("rcp.state.messages")
        frames = page.evaluate("rcp.vr.frames")
        head_turned(page, 1.2)
        turned = shot(page)
        assert np.abs(turned - ahead).mean() > 10
        assert page.evaluate("rcp.vr.frames") > frames
        assert len(page.ws_sent) == sent and page.evaluate("rcp.state.messages") == counted
        rate = page.evaluate(XR_RATE)
        print(f"\nVR: {rate:.1f} headset frames a second, both eyes drawn in each, {len(page.ws_sent) - sent} messages")
        assert len(page.ws_sent) == sent
        head_turned(page, 1.2)  # as it was before the second of turning
        shot(page)  # a frame drawn with it
        # the thumbstick pushed forward walks along the head's heading: cameras sent, each a new eye
        eye = camera["eye"]
        page.evaluate("xrDevice.controllers.right.updateAxes('thumbstick', 0, -1)")
        page.wait_for_function("(n) => rcp.state.messages > n", arg=counted, timeout=10_000)
        page.wait_for_timeout(300)
        page.evaluate("xrDevice.controllers.right.updateAxes('thumbstick', 0, 0)")
        messages = [json.loads(m) for m in page.ws_sent[sent:]]
        assert {m["type"] for m in messages} == {"move", "camera"}  # it walks through the server's collisions
        moved = [m for m in messages if m["type"] == "camera"]
        assert moved and all(m["stereo"] == "top-bottom" for m in moved)
        step = np.subtract(moved[-1]["eye"], eye)
        assert abs(step[1]) < 1e-9 and np.hypot(step[0], step[2]) > 0.05  # level, and somewhere
        # the head turned left by 1.2 rad from the panorama's heading: the walk goes that way
        hx, _, hz = np.subtract(camera["look_at"], camera["eye"]) / np.linalg.norm(
            np.subtract(camera["look_at"], camera["eye"])
        )
        c, s = math.cos(1.2), math.sin(1.2)
        expected = np.array([hx * c + hz * s, 0.0, -hx * s + hz * c])  # the heading turned about +y
        assert np.dot(step / np.linalg.norm(step), expected) > 0.99
        # leaving VR (from the headset: the emulator's view covers the page) goes back to the mono panorama
        page.evaluate("rcp.vr.session.end()")
        page.wait_for_function("rcp.vr.session === null", timeout=10_000)
        assert page.evaluate("rcp.sent.filter((m) => 'stereo' in m).at(-1)")["stereo"] == "mono"  # not a move
