"""What a server keeps across a restart (``service/store.py``), against real ``rcp serve`` processes on loopback:
an uploaded scene keeps its name and paints the same, a video killed mid-film (``kill -9``) resumes from its last
frame written and is, frame for frame, the uninterrupted run's; two servers cannot share one data folder."""

from __future__ import annotations

import io
import subprocess
import sys

import av
import httpx
import numpy as np
from helpers import uploads as files
from helpers.servers import free_port, job_status, rcp_environment, rcp_serve

PATH = {  # 41 frames around the uploaded box
    "fps": 20,
    "keyframes": [
        {"t": 0, "eye": [0, 1, 3], "look_at": [0, 0, 0]},
        {"t": 2, "eye": [3, 1.5, 0], "look_at": [0, 0, 0], "fov": 45},
    ],
}
RENDER = {"width": 64, "height": 48, "paint": {"lambda_p": 6.0}}


def wait_for(client: httpx.Client, video_id: str, until) -> dict:
    return job_status(client, f"/api/videos/{video_id}", until)


def film(client: httpx.Client, video_id: str) -> list[np.ndarray]:
    status = wait_for(client, video_id, lambda s: s["state"] not in ("queued", "running"))
    assert status["state"] == "done", status
    data = client.get(f"/api/videos/{video_id}/file").content
    with av.open(io.BytesIO(data)) as container:
        return [frame.to_ndarray(format="rgb24") for frame in container.decode(video=0)]


def test_a_restart_after_kill_9_keeps_the_upload_and_finishes_the_film_frame_for_frame(tmp_path):
    data = tmp_path / "data"
    video = {"path": PATH, "width": 128, "height": 96, "temporal": 2, "paint": {"lambda_p": 6.0, "lambda_e": 0.02}}
    with rcp_serve(tmp_path, data=str(data), threads="1") as first:  # one thread: the film takes a while
        with httpx.Client(base_url=first.url, timeout=60) as client:
            info = client.post("/api/scenes", files={"file": ("Box.glb", files.glb())}).json()
            name = info["name"]
            before = client.post("/api/render", json={"scene": name, **RENDER})
            assert before.status_code == 200
            job = client.post("/api/videos", json={"scene": name, **video}).json()
            assert job["frames"] == 41
            seen = wait_for(client, job["id"], lambda s: s["done_frames"] >= 3)
        first.process.kill()  # kill -9, mid-film
        first.process.wait()
    assert seen["state"] == "running" and seen["done_frames"] < 41
    with (
        rcp_serve(tmp_path, data=str(data), threads="1") as again,
        httpx.Client(base_url=again.url, timeout=60) as client,
    ):
        assert client.get(f"/api/scenes/{name}").json() == info
        after = client.post("/api/render", json={"scene": name, **RENDER})
        assert after.status_code == 200 and after.content == before.content
        # a second server on the same data folder is refused at once, in one line
        second = subprocess.run(
            [sys.executable, "-m", "rcp_server.cli", "serve", "--port", str(free_port())],
            env=rcp_environment(data=str(data)),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert second.returncode == 2
        assert second.stderr.strip().splitlines() == [
            f"rcp: error: the data folder {data} is in use by another server (pid {again.process.pid}); give this "
            "one its own RCP_DATA"
        ]
        resumed = client.get(f"/api/videos/{job['id']}").json()
        assert resumed["done_frames"] >= seen["done_frames"] - 1  # the frames written are kept
        resumed_film = film(client, job["id"])
        log = again.log.read_text()
        assert f"video {job['id']} resumes at frame " in log
        at = int(log.split(f"video {job['id']} resumes at frame ")[1].split()[0])
        assert at >= max(seen["done_frames"] - 1, 1)
        uninterrupted = client.post("/api/videos", json={"scene": name, **video}).json()
        expected = film(client, uninterrupted["id"])
    assert len(resumed_film) == len(expected) == 41
    for got, want in zip(resumed_film, expected, strict=True):
        np.testing.assert_array_equal(got, want)
    assert not np.array_equal(expected[0], expected[-1])
