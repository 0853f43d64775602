"""An uploaded glTF's animated camera, through the sandbox: offered by name with the scene, its path's cameras
from ``POST /api/paths`` are the animation's, and ``POST /api/videos`` paints it."""

from __future__ import annotations

import httpx
import numpy as np
import pytest
from helpers.gltf import animated_camera, expected_camera
from helpers.servers import BackgroundServer, job_status


@pytest.fixture(scope="module")
def server():
    with BackgroundServer(settle_ms=50, upload_max_bytes=1 << 20) as live:
        with httpx.Client(base_url=live.url, timeout=120) as client:
            yield client


def test_an_uploaded_animated_camera_is_offered_played_and_filmed(server):
    answer = server.post("/api/scenes", files={"file": ("shot.glb", animated_camera().glb())})
    assert answer.status_code == 201, answer.text
    scene = answer.json()
    assert scene["motions"] == ["Shot"]
    played = server.post("/api/paths", json={"scene": scene["name"], "path": {"camera": "Shot", "fps": 4}})
    assert played.status_code == 200, played.text
    cameras = played.json()["cameras"]
    assert len(cameras) == 11  # 0 to 2.5 s at 4 fps
    eye, forward, _, fov = expected_camera(np.arange(11) / 4)
    np.testing.assert_allclose([c["eye"] for c in cameras], eye, atol=1e-6)
    aim = np.subtract([c["look_at"] for c in cameras], [c["eye"] for c in cameras])
    np.testing.assert_allclose(aim / np.linalg.norm(aim, axis=1, keepdims=True), forward, atol=1e-6)
    np.testing.assert_allclose([c["fov"] for c in cameras], fov, atol=1e-6)

    body = {"scene": scene["name"], "path": {"camera": "Shot", "fps": 2}, "width": 32, "height": 24}
    created = server.post("/api/videos", json=body)
    assert created.status_code == 202, created.text
    assert created.json()["frames"] == 6
    status = job_status(server, f"/api/videos/{created.json()['id']}")
    assert status["state"] == "done", status

    unknown = server.post("/api/videos", json={**body, "path": {"camera": "Nope"}})
    assert unknown.status_code == 422
    assert unknown.json()["detail"] == "camera:Nope: the scene has no animated camera 'Nope' (it has: 'Shot')"


def test_a_hostile_camera_animation_is_refused_at_the_upload_in_one_line(server):
    builder = animated_camera([(2, "translation", [0.0, 1.0], [[0, 0, 5], [float("nan"), 0, 5]], "LINEAR")])
    answer = server.post("/api/scenes", files={"file": ("nan.glb", builder.glb())})
    assert answer.status_code == 422, answer.text
    detail = answer.json()["detail"]
    assert (
        "\n" not in detail
        and "the animation of camera 'Shot': translation: its keys hold numbers that are not finite" in detail
    )
