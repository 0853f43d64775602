"""``/api/prints`` on a real server: a print is the painting, in bands, as a PNG with its alpha and bits;
progress in rows, cancel mid-painting, the work and disk limits and bad input in one line."""

from __future__ import annotations

import io

import av
import httpx
import numpy as np
import pytest
from helpers.scenes import SPINNING_BOX
from helpers.servers import FINISHED, BackgroundServer, job_status

from rcp_server.painting.loop import paint
from rcp_server.scene.scenefile import load_scene


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scenes")
    (folder / "tiny.toml").write_text(SPINNING_BOX)
    return folder


@pytest.fixture(scope="module")
def server(scenes):
    with BackgroundServer(scenes=scenes, max_print_work=1 << 26, video_disk_bytes=64 << 20) as live:
        with httpx.Client(base_url=live.url, timeout=60) as client:
            yield client


def wait(server, print_id, states=FINISHED) -> dict:
    return job_status(server, f"/api/prints/{print_id}", lambda status: status["state"] in states)


def test_a_print_is_the_painting_with_its_alpha_and_sixteen_bits(server, scenes):
    body = {"scene": "tiny", "width": 120, "height": 80, "alpha": True, "bits": 16}
    created = server.post("/api/prints", json=body)
    assert created.status_code == 202, created.text
    assert created.json()["rows"] == 80
    status = wait(server, created.json()["id"])
    assert status["state"] == "done" and status["done_rows"] == 80, status
    answer = server.get(f"/api/prints/{status['id']}/file")
    assert answer.status_code == 200 and answer.headers["content-type"] == "image/png"
    with av.open(io.BytesIO(answer.content)) as container:
        pixels = next(container.decode(video=0)).to_ndarray(format="rgba64le")
    scene = load_scene("tiny", scenes)
    expected = paint(scene, scene.camera, 120, 80, scene.paint).image
    np.testing.assert_array_equal(pixels[..., :3], np.round(np.clip(expected, 0, 1) * 65535).astype(np.uint16))
    assert set(np.unique(pixels[..., 3])) == {0, 65535}  # the box, and the sky around it
    assert 0.02 < (pixels[..., 3] > 0).mean() < 0.8
    assert server.delete(f"/api/prints/{status['id']}").json()["state"] == "done"
    assert server.get(f"/api/prints/{status['id']}").status_code == 404


def test_a_print_can_be_cancelled_while_it_paints(server):
    created = server.post(
        "/api/prints", json={"scene": "tiny", "width": 2048, "height": 2048, "paint": {"spp": 2, "iterations": 7}}
    )
    assert created.status_code == 202, created.text
    print_id = created.json()["id"]
    wait(server, print_id, states=("running", "done"))
    cancelled = server.delete(f"/api/prints/{print_id}")
    assert cancelled.status_code == 200
    status = wait(server, print_id)
    assert status["state"] == "cancelled" and status["done_rows"] < 2048, status
    assert server.get(f"/api/prints/{print_id}/file").status_code == 409


@pytest.mark.parametrize(
    ("body", "status", "said"),
    [
        ({"width": 8192, "height": 8192, "paint": {"spp": 64}}, 422, "more than the 67,108,864 one print may take"),
        ({"width": 16384, "height": 16384, "paint": {"iterations": 1}}, 422, "more than the"),
        ({"width": 4096, "height": 4096, "paint": {"iterations": 1}, "bits": 16, "alpha": True}, 507, "bytes"),
        ({"paint": {"objects": {"ghost": {"lambda_p": 1}}}}, 422, "this scene has no 'ghost'"),
        ({"scene": "nope"}, 404, "nope"),
    ],
)
def test_prints_over_a_limit_or_badly_asked_are_refused_in_one_line(server, body, status, said):
    answer = server.post("/api/prints", json={"scene": "tiny", "width": 64, "height": 48, **body})
    assert answer.status_code == status, answer.text
    detail = answer.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail and said in detail


def test_bits_and_sizes_outside_the_schema_are_422(server):
    for body in ({"bits": 12}, {"width": 16385}, {"height": 0}):
        assert server.post("/api/prints", json={"scene": "tiny", **body}).status_code == 422
    assert server.get("/api/prints/none").status_code == 404
