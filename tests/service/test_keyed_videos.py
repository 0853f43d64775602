"""``POST /api/videos`` with a path that keys its painting: every frame painted with its own settings, keys the
scene cannot paint and keyed work over the limit refused in one line."""

from __future__ import annotations

import io

import av
import httpx
import numpy as np
import pytest
from helpers.scenes import SPINNING_BOX
from helpers.servers import BackgroundServer, job_status

from rcp_server.media.camerapath import parse_path
from rcp_server.painting.loop import paint
from rcp_server.scene.scenefile import load_scene
from rcp_server.util import images

KEYED = {
    "fps": 2,
    "keyframes": [
        {"t": 0, "eye": [0, 1, 4], "look_at": [0, 0.5, 0], "paint": {"lambda_p": 0}},
        {"t": 1, "eye": [3, 1.5, 2], "look_at": [0, 0.5, 0], "paint": {"style": "layered"}, "fade": 1},
    ],
}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scenes")
    (folder / "tiny.toml").write_text(SPINNING_BOX)
    return folder


@pytest.fixture(scope="module")
def server(scenes):
    with BackgroundServer(scenes=scenes, max_video_work=1 << 24) as live:
        with httpx.Client(base_url=live.url, timeout=30) as client:
            yield client


def test_a_keyed_film_paints_each_frame_with_its_own_settings(server, scenes):
    answer = server.post("/api/videos", json={"scene": "tiny", "path": KEYED, "width": 64, "height": 48})
    assert answer.status_code == 202, answer.text
    status = job_status(server, f"/api/videos/{answer.json()['id']}")
    assert status["state"] == "done", status
    video = server.get(f"/api/videos/{answer.json()['id']}/file").content
    with av.open(io.BytesIO(video)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    scene = load_scene("tiny", scenes)
    path = parse_path(KEYED).resolve(scene.camera).with_painting(scene.paint, scene.check_names)
    shots = list(path.frames())
    assert [[round(w, 3) for _, w in shot.looks] for shot in shots] == [[1.0], [0.5, 0.5], [1.0]]
    for frame, shot in zip(frames, shots, strict=True):
        image = sum(w * paint(scene, shot.camera, 64, 48, p, time=shot.scene_time).image for p, w in shot.looks)
        played = av.VideoFrame.from_ndarray(images.to_uint8(image), format="rgb24").reformat(format="yuv420p")
        mse = np.mean((frame.astype(float) - played.reformat(format="rgb24").to_ndarray()) ** 2)
        assert 10 * np.log10(255**2 / mse) > 35  # the frame is its painting, up to the codec's loss


def test_keys_that_cannot_paint_or_cost_too_much_are_refused_in_one_line(server):
    def refused(keyframes, status=422) -> str:
        answer = server.post("/api/videos", json={"scene": "tiny", "path": {**KEYED, "keyframes": keyframes}})
        assert answer.status_code == status, answer.text
        assert "\n" not in answer.json()["detail"]
        return answer.json()["detail"]

    first, second = KEYED["keyframes"]
    assert refused([first, {**second, "paint": {"objects": {"ghost": {"lambda_p": 1}}}}]).startswith(
        "keyframes.1.paint: objects: this scene has no 'ghost'"
    )
    assert refused([first, {**second, "paint": {"lambda_p": "far"}}]).startswith("keyframes.1.paint: lambda_p")
    assert "more than the" in refused([first, {**second, "paint": {"iterations": 256, "spp": 64}}])
    not_a_table = server.post(
        "/api/videos", json={"scene": "tiny", "path": {**KEYED, "keyframes": [first, {**second, "paint": [1]}]}}
    )
    assert not_a_table.status_code == 422
    where = not_a_table.json()["detail"][0]["loc"]  # the path's model may name itself among the path's kinds
    assert where[:2] == ["body", "path"] and where[-3:] == ["keyframes", 1, "paint"]


def test_a_paths_preview_names_the_painting_it_keys_on_each_frame(server, scenes):
    """``POST /api/paths`` answers what the path keys on each frame over the film's painting: that table, given
    over the film's painting (as the page sends it to its walk), is exactly the painting the film paints that
    frame with (within a cross-fade, the one it fades to)."""
    film = {"noise": 0.125, "lambda_e": 0.01}
    answer = server.post("/api/paths", json={"scene": "tiny", "path": KEYED, "paint": film})
    assert answer.status_code == 200, answer.text
    paints = answer.json()["paints"]
    scene = load_scene("tiny", scenes)
    base = scene.painting(film)
    path = parse_path(KEYED).resolve(scene.camera).with_painting(base, scene.check_names)
    shots = list(path.frames())
    assert len(paints) == len(shots) == 3
    for table, shot in zip(paints, shots, strict=True):
        assert scene.painting({**film, **table}) == shot.looks[-1][0]
        assert "noise" not in table or table["noise"] == shot.looks[-1][0].noise  # the film's own where not keyed
    # the fade's middle: the steps of the style it fades to, the decimal settings on their curves
    assert (paints[1]["mapping"], paints[1]["iterations"]) == ("normal", 16) and 0 < paints[1]["lambda_p"] < 30
    assert paints[0]["lambda_p"] == 0 and paints[0]["mapping"] == "color"
    # two keys of one setting: its curve between them (PCHIP through two points: the straight line)
    ramp = {"fps": 4, "keyframes": [{**k, "paint": {"lambda_p": 4 + 16 * k["t"]}} for k in KEYED["keyframes"]]}
    answer = server.post("/api/paths", json={"scene": "tiny", "path": ramp, "paint": film}).json()
    assert [p["lambda_p"] for p in answer["paints"]] == pytest.approx([4, 8, 12, 16, 20])
    assert {name for p in answer["paints"] for name in p} == {"lambda_p"}
    # a path that keys nothing names nothing; a film's painting the scene cannot take is refused in one line
    plain = {
        **KEYED,
        "keyframes": [{k: v for k, v in key.items() if k not in ("paint", "fade")} for key in KEYED["keyframes"]],
    }
    assert server.post("/api/paths", json={"scene": "tiny", "path": plain}).json()["paints"] == []
    refused = server.post(
        "/api/paths", json={"scene": "tiny", "path": KEYED, "paint": {"objects": {"ghost": {"lambda_p": 1}}}}
    )
    assert refused.status_code == 422 and "ghost" in refused.json()["detail"] and "\n" not in refused.json()["detail"]
