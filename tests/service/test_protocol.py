"""The wire protocol: the client's module is generated from the server's models, and a camera message builds
the engine's camera."""

from __future__ import annotations

import json
from pathlib import Path

from rcp_server.camera.camera import Camera
from rcp_server.service import protocol

ROOT = Path(__file__).resolve().parents[2]


def test_client_protocol_module_is_generated_from_the_server_models():
    assert (ROOT / "client" / "protocol.js").read_text() == protocol.client_module()


def test_camera_message_builds_the_same_camera_as_the_engine():
    message = protocol.client_message.validate_json(
        json.dumps({"type": "camera", "eye": [1, 2, 3], "look_at": [0, 0, 0]})
    )
    assert Camera(message.eye, message.look_at, message.up, message.fov) == Camera((1, 2, 3), (0, 0, 0))
