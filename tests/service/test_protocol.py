"""The wire protocol: the client's module is generated from the server's models, and a camera message builds
the engine's camera."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import jsonschema
import pytest

from rcp_server.camera.camera import COORDINATE_LIMIT, Camera
from rcp_server.service import protocol

ROOT = Path(__file__).resolve().parents[2]


def _generator():
    """tools/gen_protocol.py, which writes client/protocol.js (a tool beside the package, not part of it)."""
    spec = importlib.util.spec_from_file_location("gen_protocol", ROOT / "tools" / "gen_protocol.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_client_protocol_module_is_generated_from_the_server_models():
    assert (ROOT / "client" / "protocol.js").read_text() == _generator().client_module()


def test_the_client_module_holds_each_schema_once_and_a_type_for_every_message():
    text = (ROOT / "client" / "protocol.js").read_text()
    assert text.startswith("// @ts-check\n")
    every = protocol.schemas()
    # the camera's and the painting settings' schemas are written once; the messages refer to them
    assert text.count('"look_at": {') == 1 and text.count('"lambda_p": {') == 1
    assert text.count("...CAMERA,") == 1 and text.count("...PAINT,") == 1
    # no server message's schema: the client reads none of them, only their types
    assert '"title": "Frame"' not in text and '"title": "Ready"' not in text
    typedefs = set(re.findall(r"@typedef \{[^\n]*\} (\w+)", text))
    titles = {s["title"] for side in ("client", "server") for s in every[side].values()}
    assert {t if t != "Error" else "ErrorMessage" for t in titles} | {"ClientMessage", "ServerMessage"} <= typedefs
    assert len(every["client"]) == 7 and len(every["server"]) == 5


def test_the_camera_schema_carries_the_bounds_the_server_takes():
    camera = protocol.schemas()["camera"]
    for name in ("eye", "look_at"):
        for item in camera["properties"][name]["prefixItems"]:
            assert (item["minimum"], item["maximum"]) == (-COORDINATE_LIMIT, COORDINATE_LIMIT)
    inside = {"type": "camera", "eye": [COORDINATE_LIMIT, 0, 0], "look_at": [0, 0, 0]}
    jsonschema.validate(inside, protocol.schemas()["client"]["camera"])
    protocol.client_message.validate_python(inside)
    outside = {**inside, "eye": [COORDINATE_LIMIT * 1.01, 0, 0]}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(outside, protocol.schemas()["client"]["camera"])
    with pytest.raises(ValueError):  # pydantic's ValidationError is one
        protocol.client_message.validate_python(outside)


@pytest.mark.parametrize(
    ("text", "answers", "ident"),
    [
        ('{"type": "move", "id": 7, "eye": [0, 0, 0]}', "move", 7),
        ('{"type": "paint", "lambda_p": "x"}', "paint", None),
        ('{"type": "camera", "id": -1}', "camera", None),
        ('{"type": "constructor", "id": 3}', None, 3),
        ('{"type": "camera", "id": true}', "camera", None),
        ("[1, 2]", None, None),
        ("not json", None, None),
        (None, None, None),
    ],
)
def test_an_error_names_the_message_it_answers_when_it_can_be_read(text, answers, ident):
    error = protocol.Error.answering(text, "refused")
    assert (error.message, error.answers, error.id) == ("refused", answers, ident)


def test_camera_message_builds_the_same_camera_as_the_engine():
    message = protocol.client_message.validate_json(
        json.dumps({"type": "camera", "eye": [1, 2, 3], "look_at": [0, 0, 0]})
    )
    assert Camera(message.eye, message.look_at, message.up, message.fov) == Camera((1, 2, 3), (0, 0, 0))
