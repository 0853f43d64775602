"""Every painting setting, declared once in ``rcp_server/settings/params.py``, reaches every caller.

Each test is parametrized by the fields of ``PaintParams``: a new field fails here until it has a value in
``CHANGED`` and reaches REST, the WebSocket walk-through, ``rcp render`` and the client. A setting reaches a
path when the painting that comes back is exactly the engine's painting with it, and not the one without.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import httpx
import jsonschema
import numpy as np
import pytest
from helpers.wire import decode
from PIL import Image

from rcp_server.cli import camera_path, main
from rcp_server.painting.loop import paint
from rcp_server.service import protocol
from rcp_server.settings.params import PAINT_SETTINGS, PER, PaintParams
from rcp_server.util import images

ROOT = Path(__file__).resolve().parents[2]
FIELDS = [f.name for f in dataclasses.fields(PaintParams) if f.name not in PER]  # per object: test_per_object.py
SCENE = "sky"  # quick to load, and every setting below changes its painting at this size
W, H = 48, 27
QUALITY = 95

# a value other than the scene's for each setting, and the settings beside it under which it shows
CHANGED = {
    "mapping": ("depth", {}),
    "eye_mapping": ("depth", {"lambda_e": 0.1}),
    "iterations": (2, {}),
    "spp": (3, {}),  # at rest the walk-through refines to 2 x spp: 6, where the scene's 1 gives 4
    "lambda_p": (3.0, {}),
    "lambda_e": (0.1, {}),
    "z0": (2.0, {"mapping": "depth"}),
    "noise": (0.5, {}),
    "surface_noise": (0.5, {}),  # surface noise needs surfaces (the sky has no point): on SURFACES
    "surface_scale": (0.5, {}),
    "grain": (0.5, {"surface_noise": 0.5}),
    "hatch": (True, {"surface_noise": 0.5}),
    "seed": (7, {"noise": 0.5}),
    "z_max": (5.0, {"mapping": "depth"}),
    "method": ("image", {}),
    "edge": ("wrap", {"method": "image"}),
    "boil": (2, {"noise": 0.5}),
}
FILM_ONLY = {"boil"}
"""Settings of a film's frames after its first: a still (a film's first frame) paints as without them."""


SURFACES = "figures"  # a small scene with surfaces
ON_SURFACES = {"surface_noise", "surface_scale", "grain", "hatch"}


def _scene_name(name: str) -> str:
    return SURFACES if name in ON_SURFACES else SCENE


def _settings(name: str) -> tuple[dict, dict]:
    """(the context alone, the context with the changed setting), as names -> values."""
    value, context = CHANGED[name]
    return context, {**context, name: value}


def _painting(scene, **settings) -> np.ndarray:
    """The engine's painting of ``scene`` with its settings replaced: (H, W, 3) uint8."""
    params = dataclasses.replace(scene.paint, **settings)
    return images.to_uint8(paint(scene, scene.camera, W, H, params).image)


def _exported(name: str):
    """A JSON constant ``export const NAME = ...;`` of the generated client/protocol.js (``ENGINE_DEFAULTS``)."""
    text = (ROOT / "client" / "protocol.js").read_text()
    found = re.search(rf"^export const {name} = (.*?);$", text, re.MULTILINE | re.DOTALL)
    assert found, f"client/protocol.js exports no {name}"
    return json.loads(found.group(1))


@pytest.fixture(scope="module")
def scene(live_server):
    return live_server.app.state.service.scenes[SCENE]


@pytest.mark.parametrize("name", FIELDS)
def test_a_setting_reaches_rest(live_server, name):
    without, given = _settings(name)
    scene = live_server.app.state.service.scenes[_scene_name(name)]
    assert given[name] != getattr(scene.paint, name)
    body = {"scene": scene.name, "width": W, "height": H, "paint": given}
    response = httpx.post(f"{live_server.url}/api/render", json=body, timeout=60)
    assert response.status_code == 200, response.text
    expected = _painting(scene, **given)
    np.testing.assert_array_equal(decode(response.content), expected)
    assert np.array_equal(expected, _painting(scene, **without)) == (name in FILM_ONLY)


@pytest.mark.parametrize("name", FIELDS)
def test_a_setting_reaches_the_walk_through(walk, live_server, name):
    without, given = _settings(name)
    scene = live_server.app.state.service.scenes[_scene_name(name)]
    walk.send(type="hello", scene=scene.name, width=W, height=H, quality=QUALITY)
    assert walk.next()["type"] == "ready"
    before, _ = walk.until_final()[-1]
    walk.send(type="paint", **given)
    meta, image = walk.until_final()[-1]  # at rest: all iterations, the settings given, refined samples
    assert meta["phase"] == "refine" and (meta["width"], meta["height"]) == (W, H)

    def jpeg(settings: dict) -> np.ndarray:
        return decode(images.encode(_painting(scene, **{**settings, "spp": meta["spp"]}) / 255.0, "JPEG", QUALITY))

    np.testing.assert_array_equal(image, jpeg(given))
    if name in meta:  # the frame reports this setting (spp): it follows it
        assert meta[name] != before[name]
    else:
        assert np.array_equal(image, jpeg(without)) == (name in FILM_ONLY)


@pytest.mark.parametrize("name", FIELDS)
def test_a_setting_reaches_the_command_line(tmp_path, live_server, name):
    without, given = _settings(name)
    scene = live_server.app.state.service.scenes[_scene_name(name)]
    out = tmp_path / "still.png"

    def flag(key: str, value) -> list[str]:
        name = key.replace("_", "-")
        if isinstance(value, bool):
            return [f"--{name}" if value else f"--no-{name}"]
        return [f"--{name}", str(value)]

    flags = [part for key, value in given.items() for part in flag(key, value)]
    assert main(["-q", "render", scene.name, "--out", str(out), "--width", str(W), "--height", str(H), *flags]) == 0
    np.testing.assert_array_equal(np.asarray(Image.open(out)), _painting(scene, **given))


def test_boil_reseeds_a_films_noise_every_k_frames(tmp_path, live_server):
    scene = live_server.app.state.service.scenes[SCENE]
    size = ["--width", str(W), "--height", str(H), "--noise", "0.5", "--frames", "5", "--walk", "0.1"]
    assert main(["-q", "render", SCENE, "--out", str(tmp_path / "f.png"), "--boil", "2", *size]) == 0
    frames = [np.asarray(Image.open(tmp_path / f"f_{k:04d}.png")) for k in range(5)]
    for k, frame in enumerate(frames):
        camera = camera_path(scene.camera, k / 4, 0.0, 0.1)
        params = dataclasses.replace(scene.paint, noise=0.5, seed=k // 2)
        painted = paint(scene, camera, W, H, params, time=k / 24).image
        np.testing.assert_array_equal(frame, images.to_uint8(painted))
    plain = dataclasses.replace(scene.paint, noise=0.5)
    still = images.to_uint8(paint(scene, camera_path(scene.camera, 0.5, 0.0, 0.1), W, H, plain, time=2 / 24).image)
    assert not np.array_equal(frames[2], still)  # without the boil, frame 2 keeps seed 0


@pytest.mark.parametrize("name", FIELDS)
def test_a_setting_reaches_the_client(name):
    declared = PAINT_SETTINGS[name]
    _, given = _settings(name)
    # the client's defaults, for a setting a scene leaves out, are the engine's
    assert _exported("ENGINE_DEFAULTS")[name] == getattr(PaintParams(), name) == declared.default
    schemas = protocol.schemas()  # what protocol.js's PROTOCOL spells out (tests/client: evaluated in Chromium)
    # the panel makes a control per property of the paint schema, with its range and choices ...
    values = schemas["paint"]["properties"][name]["anyOf"][0]
    if declared.choices:
        assert values["enum"] == list(declared.choices)
    elif declared.kind is bool:
        assert values["type"] == "boolean"
    else:
        bounds = {"minimum": declared.ge, "exclusiveMinimum": declared.gt, "maximum": declared.le}
        assert {k: v for k, v in values.items() if k in bounds} == {k: v for k, v in bounds.items() if v is not None}
    # ... and messages.js sends a paint message only if this schema takes it, as the server does
    message = {"type": "paint", **given}
    jsonschema.validate(message, schemas["client"]["paint"])
    jsonschema.validate({"type": "paint", name: None}, schemas["client"]["paint"])  # null: the scene's value
    assert protocol.client_message.validate_python(message).changes() == given
