"""Styles (``rcp_server/settings/styles.py``) reach every caller: REST, the WebSocket, ``rcp render`` and the client.

A style reaches a path when the painting that comes back is exactly the engine's painting with the style's
settings over the scene's; explicit settings beside a style win over it.
"""

from __future__ import annotations

import dataclasses
import json

import httpx
import numpy as np
import pytest
from helpers.browser import SIZE, client, needs_chromium, sent, set_slider, wait_final
from helpers.wire import decode
from PIL import Image

from rcp_server.cli import main
from rcp_server.painting.loop import paint
from rcp_server.settings.params import PaintParams
from rcp_server.settings.styles import LOOK, STYLES, get_style, with_style
from rcp_server.util import images

SCENE = "sky"
W, H = 48, 27


def _painting(scene, **settings) -> np.ndarray:
    """The engine's painting of ``scene`` with its settings replaced: (H, W, 3) uint8."""
    params = dataclasses.replace(scene.paint, **settings)
    return images.to_uint8(paint(scene, scene.camera, W, H, params).image)


@pytest.fixture(scope="module")
def scene(live_server):
    return live_server.app.state.service.scenes[SCENE]


def test_every_style_sets_every_setting_of_a_look_and_paints():
    for style in STYLES.values():
        assert set(LOOK) <= set(style.settings)
        PaintParams.from_dict(style.settings)
    with pytest.raises(ValueError, match="unknown style 'nope'; styles: smudge, focus, fractured"):
        get_style("nope")
    base = PaintParams(z0=3.0, seed=4)
    styled = with_style(base, {"style": "focus", "lambda_p": 0.5})
    assert styled == dataclasses.replace(base, **{**STYLES["focus"].settings, "lambda_p": 0.5})


def test_the_styles_are_listed_with_their_settings(live_server):
    listed = httpx.get(f"{live_server.url}/api/styles", timeout=10).json()
    assert listed == [dataclasses.asdict(style) for style in STYLES.values()]


@pytest.mark.parametrize("name", list(STYLES))
def test_a_style_reaches_rest(live_server, scene, name):
    body = {"scene": SCENE, "width": W, "height": H, "paint": {"style": name}}
    response = httpx.post(f"{live_server.url}/api/render", json=body, timeout=60)
    assert response.status_code == 200, response.text
    np.testing.assert_array_equal(decode(response.content), _painting(scene, **STYLES[name].settings))


def test_explicit_settings_beat_the_style_over_rest(live_server, scene):
    body = {"scene": SCENE, "width": W, "height": H, "paint": {"lambda_p": 3.0, "style": "smudge"}}
    response = httpx.post(f"{live_server.url}/api/render", json=body, timeout=60)
    expected = _painting(scene, **{**STYLES["smudge"].settings, "lambda_p": 3.0})
    np.testing.assert_array_equal(decode(response.content), expected)
    assert not np.array_equal(expected, _painting(scene, **STYLES["smudge"].settings))


def test_an_unknown_style_gets_a_422_naming_the_styles(live_server):
    body = {"scene": SCENE, "paint": {"style": "watercolour"}}
    response = httpx.post(f"{live_server.url}/api/render", json=body, timeout=10)
    assert response.status_code == 422
    assert all(f"'{name}'" in response.json()["detail"][0]["msg"] for name in STYLES)


def test_a_style_reaches_the_walk_through_and_explicit_settings_beat_it(walk, scene):
    walk.send(type="hello", scene=SCENE, width=W, height=H, quality=95)
    assert walk.next()["type"] == "ready"
    walk.until_final()
    walk.send(type="paint", style="focus", lambda_p=0.05)
    meta, image = walk.until_final()[-1]
    settings = {**STYLES["focus"].settings, "lambda_p": 0.05, "spp": meta["spp"]}
    expected = decode(images.encode(_painting(scene, **settings) / 255.0, "JPEG", 95))
    np.testing.assert_array_equal(image, expected)
    walk.send(type="paint", style="nope")
    assert "style" in walk.next()["message"]


def test_a_style_reaches_the_command_line(tmp_path, scene, capsys):
    out = tmp_path / "still.png"
    size = ["--width", str(W), "--height", str(H)]
    assert main(["-q", "render", SCENE, "--out", str(out), *size, "--style", "layered", "--iterations", "3"]) == 0
    expected = _painting(scene, **{**STYLES["layered"].settings, "iterations": 3})
    np.testing.assert_array_equal(np.asarray(Image.open(out)), expected)
    assert main(["-q", "render", SCENE, "--out", str(out), "--style", "nope"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("rcp: error: ") and all(name in error for name in STYLES)


@needs_chromium
def test_the_client_picks_a_style_and_keeps_a_preset(browser, live_server):  # noqa: F811 - the fixture
    with client(browser, live_server.url, SCENE) as page:
        page.select_option("#style", "fractured")
        page.wait_for_function("rcp.sent.some((m) => m.type === 'paint' && m.style === 'fractured')")
        # the panel shows the style's settings, and the server paints with them (refined from its 4 spp)
        assert page.get_attribute('#paint-mapping [data-value="normal"]', "aria-pressed") == "true"
        frame = wait_final(page, page.evaluate("rcp.overlay.frame.seq"))
        assert frame["spp"] >= 2 * STYLES["fractured"].settings["spp"]
        set_slider(page, "lambda_p", 20)
        page.fill("#preset-name", "mine")
        page.click("#preset-save")
        saved = json.loads(page.evaluate("localStorage.getItem('rcp.presets')"))
        assert saved == {"mine": {"style": "fractured", "lambda_p": 20}}

        # a new page of the same browser keeps the preset (the scene's plain address: a reload would reopen the
        # view the address now carries, the style among it)
        page.goto(page.url.split("?")[0] + f"?scene={SCENE}&width={SIZE[0]}&height={SIZE[1]}")
        wait_final(page)
        assert page.evaluate("rcp.state.paint") == {}
        page.click('#presets [data-preset="mine"] .preset-apply')
        page.wait_for_function("rcp.sent.some((m) => m.type === 'paint' && m.style === 'fractured')")
        paint_sent = [m for m in sent(page, "paint") if m.get("style") == "fractured"][0]
        assert paint_sent == {"type": "paint", "style": "fractured", "lambda_p": 20}
        assert page.input_value("#style") == "fractured" and page.input_value("#paint-lambda_p") == "20"

        page.click('#presets [data-preset="mine"] .preset-delete')
        assert json.loads(page.evaluate("localStorage.getItem('rcp.presets')")) == {}
        assert page.locator("#presets li").count() == 0
