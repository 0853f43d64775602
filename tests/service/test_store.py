"""The data folder (``service/store.py``): one server per folder; what a temporal video continues from comes back
exactly; a path written out resolves to itself; and, against real servers stopped and started again on one
folder, a film stopped mid-way resumes and is the uninterrupted run's, a finished video is still served, and
uploads outlive a restart within their budgets and expire when idle."""

from __future__ import annotations

import hashlib
import io
import json
import time
from dataclasses import fields, replace

import av
import httpx
import numpy as np
import pytest
from helpers import uploads as files
from helpers.scenes import CAMERA, SPINNING_BOX
from helpers.servers import BackgroundServer, job_status

from rcp_server.media.camerapath import PathSpec, parse_path
from rcp_server.painting.loop import paint
from rcp_server.service.store import DataFolderError, Store, load_state, save_state
from rcp_server.service.videos import ANY_CAMERA, path_spec
from rcp_server.settings.params import PaintParams

PATH = {
    "fps": 10,
    "keyframes": [
        {"t": 0, "eye": [0, 1, 4], "look_at": [0, 0.5, 0]},
        {"t": 2, "eye": [3, 1.5, 2], "look_at": [0, 0.5, 0], "fov": 45},
    ],
}


def test_a_data_folder_takes_one_server_at_a_time(tmp_path):
    store = Store(tmp_path)
    with pytest.raises(DataFolderError) as refused:
        Store(tmp_path)
    assert str(refused.value) == (
        f"the data folder {tmp_path} is in use by another server (pid {__import__('os').getpid()}); give this one "
        "its own RCP_DATA"
    )
    store.close()
    Store(tmp_path).close()  # let go of, it takes the next one
    (tmp_path / "a file").write_text("")
    with pytest.raises(DataFolderError, match=f"^cannot use the data folder {tmp_path}/a file: File exists$"):
        Store(tmp_path / "a file")


def test_the_state_a_temporal_video_continues_from_comes_back_exactly(tmp_path, busy_scene):
    params = PaintParams(iterations=2, mapping="normal", eye_mapping="test-probe", lambda_e=0.01)
    state = paint(busy_scene, CAMERA, 24, 18, params, threads=1).state
    save_state(tmp_path / "state.npz", 7, state)
    index, loaded = load_state(tmp_path / "state.npz", 1 << 24)
    assert index == 7 and loaded.region == state.region and loaded.blank == state.blank
    for field in fields(state):
        if isinstance(getattr(state, field.name), np.ndarray):
            np.testing.assert_array_equal(getattr(loaded, field.name), getattr(state, field.name))
            assert getattr(loaded, field.name).dtype == getattr(state, field.name).dtype
    assert loaded.depth is not None and loaded.normal is not None  # the channels the mappings read
    step = replace(params, iterations=1)
    again = paint(busy_scene, CAMERA, 24, 18, step, previous=loaded, threads=1).image
    np.testing.assert_array_equal(again, paint(busy_scene, CAMERA, 24, 18, step, previous=state, threads=1).image)
    assert load_state(tmp_path / "nothing.npz", 1 << 24) is None


def test_a_resolved_path_written_out_resolves_to_itself():
    path = parse_path(PATH).resolve(CAMERA)
    written = json.loads(json.dumps(path_spec(path)))
    assert PathSpec.model_validate(written).resolve(ANY_CAMERA) == path


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scenes")
    (folder / "tiny.toml").write_text(SPINNING_BOX)
    return folder


def wait_for(client, video_id, until) -> dict:
    return job_status(client, f"/api/videos/{video_id}", until)


def decoded(data: bytes) -> list[np.ndarray]:
    with av.open(io.BytesIO(data)) as container:
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]


def test_a_film_stopped_mid_way_resumes_and_a_finished_one_is_still_served(tmp_path, scenes, caplog):
    caplog.set_level("INFO", "rcp.service")
    data = tmp_path / "data"
    body = {"scene": "tiny", "path": PATH, "width": 128, "height": 96, "paint": {"spp": 2}}
    with (
        BackgroundServer(scenes=scenes, data=data, threads=1) as live,
        httpx.Client(base_url=live.url, timeout=60) as client,
    ):
        job = client.post("/api/videos", json=body).json()
        queued = client.post("/api/videos", json={**body, "width": 32, "height": 24}).json()  # waits its turn
        seen = wait_for(client, job["id"], lambda s: s["done_frames"] >= 2)
    assert seen["state"] == "running" and seen["done_frames"] < job["frames"] == 21
    with Store(data) as store:
        record, waiting = store.videos()
        assert record.state == "running" and record.done_frames >= 2  # a stop is not a failure
        assert waiting.id == queued["id"] and waiting.state == "queued"
        assert len(list(store.frames_dir(job["id"]).glob("frame_*.png"))) == record.done_frames
    with BackgroundServer(scenes=scenes, data=data) as live, httpx.Client(base_url=live.url, timeout=60) as client:
        done = wait_for(client, job["id"], lambda s: s["state"] not in ("queued", "running"))
        assert f"video {job['id']} resumes at frame {record.done_frames} of 21" in caplog.messages
        assert done == {**seen, "state": "done", "done_frames": 21, "message": done["message"]}
        assert wait_for(client, queued["id"], lambda s: s["state"] not in ("queued", "running"))["state"] == "done"
        resumed = client.get(f"/api/videos/{job['id']}/file").content
        fresh = client.post("/api/videos", json=body).json()
        wait_for(client, fresh["id"], lambda s: s["state"] == "done")
        expected = client.get(f"/api/videos/{fresh['id']}/file").content
    assert len(decoded(resumed)) == 21
    for got, want in zip(decoded(resumed), decoded(expected), strict=True):
        np.testing.assert_array_equal(got, want)
    size = len(resumed)
    with (
        BackgroundServer(scenes=scenes, data=data, video_disk_bytes=size) as live,
        httpx.Client(base_url=live.url, timeout=60) as client,
    ):
        assert client.get(f"/api/videos/{job['id']}").json() == done
        refused = client.post("/api/videos", json=body)  # the stored videos count against the disk budget
        assert refused.status_code == 507 and f"have 0 of their {size:,} left" in refused.json()["detail"]
        kept = client.get(f"/api/videos/{job['id']}/file")
        assert kept.status_code == 200 and kept.content == resumed
        for other in (fresh, queued):
            assert client.delete(f"/api/videos/{other['id']}").status_code == 200
    assert sorted(p.name for p in (data / "videos").iterdir()) == [f"{job['id']}.mp4"]
    time.sleep(1.1)
    with BackgroundServer(scenes=scenes, data=data, video_keep_s=1.0) as live:
        assert httpx.get(f"{live.url}/api/videos/{job['id']}").status_code == 404  # expired while it was down
    assert list((data / "videos").iterdir()) == []


def upload(client, name: str) -> str:
    answer = client.post("/api/scenes", files={"file": (name, files.glb())})
    assert answer.status_code == 201, answer.text
    return answer.json()["name"]


def test_uploads_outlive_a_restart_within_their_budgets_and_expire_when_idle(tmp_path):
    data = tmp_path / "data"
    render = {"width": 32, "height": 24}
    with BackgroundServer(data=data) as live, httpx.Client(base_url=live.url, timeout=60) as client:
        names = [upload(client, f"box{k}.glb") for k in range(3)]
        images = {name: client.post("/api/render", json={"scene": name, **render}).content for name in names}
        time.sleep(0.01)
        assert client.post("/api/render", json={"scene": names[0], **render}).status_code == 200  # used last
    assert sorted(p.name for p in (data / "uploads").iterdir()) == sorted(names)
    with (
        BackgroundServer(data=data, upload_max_scenes=2) as live,
        httpx.Client(base_url=live.url, timeout=60) as client,
    ):
        # the two used last are kept (the first one, used after the third was uploaded, and the third)
        for name in (names[0], names[2]):
            assert client.post("/api/render", json={"scene": name, **render}).content == images[name]
        assert client.get(f"/api/scenes/{names[1]}").status_code == 404
        full = client.post("/api/scenes", files={"file": ("more.glb", files.glb())})
        assert full.status_code == 503 and "at most 2 uploaded scenes" in full.json()["detail"]
        assert client.delete(f"/api/scenes/{names[0]}").status_code == 204
    assert [p.name for p in (data / "uploads").iterdir()] == [names[2]]
    with Store(data) as store:
        assert [r.name for r in store.uploads()] == [names[2]]
    time.sleep(1.1)
    with BackgroundServer(data=data, upload_idle_s=1.0) as live:
        assert httpx.get(f"{live.url}/api/scenes/{names[2]}").status_code == 404  # idle while the server was down
    assert list((data / "uploads").iterdir()) == []


def test_an_upload_is_recorded_with_its_sizes_and_the_hash_of_the_token_it_came_with(tmp_path):
    data = tmp_path / "data"
    with BackgroundServer(data=data, token="sesame") as live:
        auth = {"authorization": "Bearer sesame"}
        with httpx.Client(base_url=live.url, timeout=60, headers=auth) as client:
            clock = time.time()
            name = upload(client, "Box.glb")
    with Store(data) as store:
        (record,) = store.uploads()
    folder = data / "uploads" / name
    assert sorted(p.name for p in folder.iterdir()) == ["original", "parts.npz"]
    assert (folder / "original").read_bytes() == files.glb()
    assert record.name == name and record.title == "Box"
    assert record.owner == hashlib.sha256(b"sesame").hexdigest()
    assert record.file_bytes == sum(p.stat().st_size for p in folder.iterdir())
    assert record.weight > 0 and clock <= record.created <= record.used <= time.time()


def test_an_upload_a_stored_film_still_paints_is_in_use_however_long_the_server_was_down(tmp_path):
    data = tmp_path / "data"
    body = {"path": PATH, "width": 128, "height": 96, "paint": {"spp": 2}}
    with (
        BackgroundServer(data=data, threads=1) as live,
        httpx.Client(base_url=live.url, timeout=60) as client,
    ):
        name = upload(client, "Box.glb")
        job = client.post("/api/videos", json={"scene": name, **body}).json()
        seen = wait_for(client, job["id"], lambda s: s["done_frames"] >= 1)
    assert seen["state"] == "running"
    time.sleep(3.1)  # down longer than an upload may stay idle (3 s: room for the film to finish on a busy machine)
    with (
        BackgroundServer(data=data, upload_idle_s=3.0) as live,
        httpx.Client(base_url=live.url, timeout=60) as client,
    ):
        done = wait_for(client, job["id"], lambda s: s["state"] not in ("queued", "running"))
        assert done["state"] == "done", done
        assert client.get(f"/api/scenes/{name}").status_code == 200
