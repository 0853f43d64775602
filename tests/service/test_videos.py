"""``/api/videos`` on a real server: a path becomes an MP4 of the engine's paintings; jobs are watched,
cancelled mid-painting, refused over their limits, and expire; bad input is a 4xx in one line."""

from __future__ import annotations

import io
import re
import time
from dataclasses import asdict

import av
import httpx
import numpy as np
import pytest
from helpers.scenes import CAMERA, SPINNING_BOX, make_scene
from helpers.servers import FINISHED, BackgroundServer, job_status
from helpers.waits import wait_until
from PIL import Image

from rcp_server.cluster.painter import Backoff
from rcp_server.media.camerapath import parse_path
from rcp_server.painting.loop import paint
from rcp_server.scene.scenefile import load_scene
from rcp_server.service.memory import Budget
from rcp_server.service.painter import LocalPainter, PainterFailed
from rcp_server.service.refusal import Refusal
from rcp_server.service.settings import Settings
from rcp_server.service.store import Store, VideoRecord, VideoSettings
from rcp_server.service.videos import VideoRefused, Videos, film_bytes, path_spec, video_bytes
from rcp_server.service.workshop import Workshop
from rcp_server.settings.params import PaintParams
from rcp_server.util import images

PATH = {
    "fps": 6,
    "keyframes": [
        {"t": 0, "eye": [0, 1, 4], "look_at": [0, 0.5, 0]},
        {"t": 1, "eye": [3, 1.5, 2], "look_at": [0, 0.5, 0], "fov": 45},
    ],
}
LONG = {**PATH, "fps": 60, "keyframes": [PATH["keyframes"][0], {**PATH["keyframes"][1], "t": 60}]}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scenes")
    (folder / "tiny.toml").write_text(SPINNING_BOX)
    return folder


@pytest.fixture(scope="module")
def server(scenes):
    with BackgroundServer(scenes=scenes, max_video_work=1 << 26, max_videos=1, max_videos_waiting=1) as live:
        with httpx.Client(base_url=live.url, timeout=30) as client:
            yield client


def wait_video(client, video_id, states=FINISHED) -> dict:
    return job_status(client, f"/api/videos/{video_id}", lambda status: status["state"] in states)


def one_line(answer: httpx.Response, status: int) -> str:
    assert answer.status_code == status, answer.text
    detail = answer.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail
    return detail


def test_a_path_becomes_an_mp4_of_its_paintings(server, scenes):
    answer = server.post("/api/videos", json={"scene": "tiny", "path": PATH, "width": 64, "height": 48})
    assert answer.status_code == 202, answer.text
    created = answer.json()
    assert created["frames"] == 7
    status = wait_video(server, created["id"])
    assert status | {"message": ""} == {**created, "state": "done", "done_frames": 7, "message": ""}, status
    video = server.get(f"/api/videos/{created['id']}/file")
    assert video.status_code == 200 and video.headers["content-type"] == "video/mp4"
    with av.open(io.BytesIO(video.content)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == 7 and frames[0].shape == (48, 64, 3)
    scene = load_scene("tiny", scenes)
    for frame, shot in zip(frames, parse_path(PATH).resolve(scene.camera).frames(), strict=True):
        expected = images.to_uint8(paint(scene, shot.camera, 64, 48, scene.paint, time=shot.scene_time).image)
        played = av.VideoFrame.from_ndarray(expected, format="rgb24").reformat(format="yuv420p")
        mse = np.mean((frame.astype(float) - played.reformat(format="rgb24").to_ndarray()) ** 2)
        assert 10 * np.log10(255**2 / mse) > 35  # the frame is the painting, up to the codec's loss
    # deleted: gone, file and all
    assert server.delete(f"/api/videos/{created['id']}").json()["state"] == "done"
    assert server.get(f"/api/videos/{created['id']}").status_code == 404
    assert server.get(f"/api/videos/{created['id']}/file").status_code == 404


def test_a_video_takes_a_style_as_a_render_does(server, scenes):
    """``"style"`` in a video's ``paint``: the style's settings, the explicit ones beside it winning."""
    paint_settings = {"style": "fractured", "iterations": 2}
    body = {"scene": "tiny", "path": {**PATH, "fps": 1}, "width": 32, "height": 24, "paint": paint_settings}
    answer = server.post("/api/videos", json=body)
    assert answer.status_code == 202, answer.text
    assert wait_video(server, answer.json()["id"])["state"] == "done"
    frame = server.get(f"/api/videos/{answer.json()['id']}/file").content
    with av.open(io.BytesIO(frame)) as container:
        first = next(container.decode(video=0)).to_ndarray(format="rgb24")
    camera = {k: v for k, v in PATH["keyframes"][0].items() if k != "t"}
    render = {"scene": "tiny", "width": 32, "height": 24, "camera": camera, "paint": paint_settings}
    png = server.post("/api/render", json=render)
    assert png.status_code == 200, png.text
    expected = np.asarray(Image.open(io.BytesIO(png.content)).convert("RGB"))
    played = av.VideoFrame.from_ndarray(expected, format="rgb24").reformat(format="yuv420p")
    mse = np.mean((first.astype(float) - played.reformat(format="rgb24").to_ndarray()) ** 2)
    assert 10 * np.log10(255**2 / mse) > 35
    refused = server.post("/api/videos", json={**body, "paint": {"style": "nope"}})
    assert refused.status_code == 422 and refused.json()["detail"][0]["loc"] == ["body", "paint", "style"]


def test_cancelling_stops_the_painting_and_the_server_goes_on(server):
    created = server.post("/api/videos", json={"scene": "tiny", "path": LONG, "width": 64, "height": 48}).json()
    wait_video(server, created["id"], states=("running",))
    # one job paints and one waits: the next one is told to come back later
    waiting = server.post("/api/videos", json={"scene": "tiny", "path": LONG, "width": 64, "height": 48})
    assert waiting.status_code == 202
    full = server.post("/api/videos", json={"scene": "tiny", "path": PATH, "width": 64, "height": 48})
    assert "busy" in one_line(full, 503) and int(full.headers["retry-after"]) > 0
    assert server.delete(f"/api/videos/{waiting.json()['id']}").json()["state"] == "cancelled"
    assert server.get(f"/api/videos/{created['id']}/file").status_code == 409  # not done
    assert server.delete(f"/api/videos/{created['id']}").status_code == 200
    status = wait_video(server, created["id"])
    assert status["state"] == "cancelled" and status["done_frames"] < status["frames"] == 3601  # stopped mid-way
    wait_until(lambda: not server.get("/api/health").json()["painting"])
    assert server.post("/api/render", json={"scene": "tiny", "width": 32, "height": 32}).status_code == 200


@pytest.mark.parametrize(
    ("body", "status", "says"),
    [
        ({"scene": "nowhere"}, 404, "unknown scene 'nowhere'"),
        ({"width": 63}, 422, "even width and height, got 63x48"),
        ({"path": {**PATH, "keyframes": PATH["keyframes"][::-1]}}, 422, "keyframes.1.t: must be greater"),
        (
            {"path": {**PATH, "keyframes": [PATH["keyframes"][0], {"t": 1, "eye": [0, 1, 4], "look_at": [0, 1, 4]}]}},
            422,
            "keyframes.1: eye and look_at coincide",
        ),
        (
            {"path": {**PATH, "fps": 240, "keyframes": [PATH["keyframes"][0], {**PATH["keyframes"][1], "t": 3600}]}},
            422,
            "more than the 100,000 a path may have",
        ),
        ({"path": LONG, "paint": {"spp": 64}}, 422, "more than the 67,108,864 one video may take"),
    ],
)
def test_bad_jobs_are_refused_in_one_line(server, body, status, says):
    answer = server.post("/api/videos", json={"scene": "tiny", "path": PATH, "width": 64, "height": 48, **body})
    assert says in one_line(answer, status)


AT_THE_LIMIT = [  # keyframes at the coordinate limit, whose curve carries the look-at just past it between them
    {"t": 0, "eye": [0, 0, 5], "look_at": [-1e9, 0, 0]},
    {"t": 1, "eye": [0, 0, 6], "look_at": [-1e9, 1e9, 0]},
    {"t": 2, "eye": [0, 0, 6], "look_at": [-1e9, 0, -1e9]},
]
CLOSE = [PATH["keyframes"][0], {**PATH["keyframes"][1], "t": 1e-300}]  # scipy: "`dydx` must contain only finite"


@pytest.mark.parametrize(
    ("path", "says"),
    [
        ({**PATH, "keyframes": CLOSE}, "keyframes.1.t: must be greater than the previous keyframe's t, by 0.001 s"),
        ({**PATH, "loop": True, "keyframes": [CLOSE[0], {**CLOSE[1], "t": 5e-324}]}, "by 0.001 s at least"),
        ({**PATH, "keyframes": AT_THE_LIMIT}, "frame 3 (t = 0.5 s), between them, is not valid: look_at must lie"),
    ],
)
def test_a_path_that_would_fail_later_is_refused_when_it_is_given(server, path, says):
    """Its preview was a 500, its video a 202 and then a failed job: every camera a path will ask of its curves
    is checked when the path is given."""
    assert says in one_line(server.post("/api/paths", json={"scene": "tiny", "path": path}), 422)
    video = server.post("/api/videos", json={"scene": "tiny", "path": path, "width": 32, "height": 32})
    assert says in one_line(video, 422)


def test_bad_bodies_and_unknown_ids_are_4xx(server):
    assert server.post("/api/videos", json={"scene": "tiny"}).status_code == 422  # no path
    text = '{"scene": "tiny", "path": {"keyframes": [{"t": NaN, "eye": [0,0,0], "look_at": [0,0,1]}]}}'
    assert server.post("/api/videos", content=text, headers={"content-type": "application/json"}).status_code == 422
    assert server.post("/api/videos", json={"scene": "tiny", "path": PATH, "format": "gif"}).status_code == 422
    assert "no video 'nothing'" in one_line(server.get("/api/videos/nothing"), 404)
    assert server.get("/api/videos/nothing/file").status_code == 404
    assert server.delete("/api/videos/nothing").status_code == 404


def test_a_video_past_the_disk_budget_is_refused_at_submission_with_507(scenes, tmp_path):
    """The 507 comes when the job is submitted (it was accepted and failed halfway), with the estimate and the
    room left, the estimates of the jobs in progress counted: of two that fit one at a time, the second waits."""
    path = {**PATH, "fps": 60}  # 61 frames: the first job is still painting when the second comes
    body = {"scene": "tiny", "path": path, "width": 32, "height": 32}
    estimate = video_bytes(32, 32, parse_path(path).resolve(load_scene("tiny", scenes).camera).frame_count)
    settings = {"scenes": scenes, "video_disk_bytes": estimate * 3 // 2, "data": tmp_path}
    with BackgroundServer(**settings) as live, httpx.Client(base_url=live.url, timeout=30) as client:
        first = client.post("/api/videos", json=body)
        second = client.post("/api/videos", json=body)
        assert first.status_code == 202
        said = one_line(second, 507)
        assert (
            f"about {estimate:,} bytes" in said
            and re.search(rf"have [\d,]+ of their {estimate * 3 // 2:,} left", said)  # the running job's frames vary
        )
        assert wait_video(client, first.json()["id"])["state"] == "done"
    with BackgroundServer(scenes=scenes, video_disk_bytes=1) as live, httpx.Client(base_url=live.url) as client:
        assert "have 1 of their 1 left" in one_line(client.post("/api/videos", json=body), 507)


class StillPainting:
    """A painter in place of Ray's that paints nothing until its job is stopped: the job stays running."""

    def film(self, scene, path, width, height, params, temporal, start, previous, should_stop):
        while not should_stop():
            time.sleep(0.01)
        yield from ()


def test_a_job_resumed_from_the_last_run_reserves_its_estimate_at_submission(tmp_path):
    """A job the last run left queued comes back at start-up and counts at the door as this run's jobs do."""
    path = parse_path(PATH).resolve(CAMERA)
    estimate = video_bytes(32, 32, path.frame_count)
    given = {"path": path_spec(path), "width": 32, "height": 32, "params": asdict(PaintParams()), "temporal": None}
    settings = Settings(data=tmp_path, threads=1, video_disk_bytes=estimate * 3 // 2)
    workshop = Workshop(1, 1)
    scene = make_scene()
    with Store(tmp_path) as store:
        store.add_video(
            VideoRecord(
                id="0123456789abcdef",
                scene="tiny",
                settings=VideoSettings.model_validate(given),
                frames=path.frame_count,
                state="queued",
                done_frames=0,
                message="",
                created=0.0,
                finished=None,
                bytes=0,
            )
        )
        videos = Videos(settings, workshop, store, StillPainting(), Budget(settings.memory_bytes))
        try:
            videos.resume(lambda name: scene if name == "tiny" else None)
            assert videos.get("0123456789abcdef").state in ("queued", "running")
            with pytest.raises(VideoRefused) as refused:
                videos.submit(scene, path, 32, 32, PaintParams(), None)
            assert refused.value.status == 507
            assert f"have {estimate // 2:,} of their {estimate * 3 // 2:,} left" in str(refused.value)
        finally:
            videos.close()
            workshop.close()


def test_a_film_counts_every_byte_it_writes_and_stops_at_the_budget_keeping_its_frames(scenes, tmp_path, monkeypatch):
    """The estimate lets it in (it falls short here); the PNG frames it writes count against RCP_VIDEO_DISK_BYTES
    as they are written, and the frame that would pass it stops the film with 507 naming the setting. What it
    made stays on disk, counted, until the job expires (then it goes)."""
    monkeypatch.setattr("rcp_server.service.videos.video_bytes", lambda width, height, frames: 0)  # falls short
    settings = {"scenes": scenes, "video_disk_bytes": 4_000, "video_keep_s": 1.0, "data": tmp_path}
    path = {**PATH, "fps": 24}
    with BackgroundServer(**settings) as live, httpx.Client(base_url=live.url, timeout=30) as client:
        created = client.post("/api/videos", json={"scene": "tiny", "path": path, "width": 32, "height": 32}).json()
        status = wait_video(client, created["id"])
        made = status["done_frames"]
        assert status["state"] == "failed" and 0 < made < status["frames"] == 25, status
        assert status["message"] == (
            f"507: the videos would use more than the 4,000 bytes of RCP_VIDEO_DISK_BYTES: stopped after {made} "
            "frames, kept until the video expires or is deleted"
        )
        kept = sorted((tmp_path / "videos" / created["id"]).iterdir())
        assert [f.name for f in kept] == [f"frame_{k:06d}.png" for k in range(made)]
        assert sum(f.stat().st_size for f in kept) <= 4_000
        time.sleep(1.2)
        assert client.get(f"/api/videos/{created['id']}").status_code == 404  # expired
        assert list((tmp_path / "videos").iterdir()) == []  # and its frames with it


def test_cancelling_twice_keeps_the_cancelled_job_until_it_expires(scenes, tmp_path):
    settings = {"scenes": scenes, "max_videos": 1, "max_videos_waiting": 1, "video_keep_s": 600, "data": tmp_path}
    with BackgroundServer(**settings) as live, httpx.Client(base_url=live.url, timeout=30) as client:
        running = client.post("/api/videos", json={"scene": "tiny", "path": LONG, "width": 64, "height": 48}).json()
        waiting = client.post("/api/videos", json={"scene": "tiny", "path": PATH, "width": 64, "height": 48}).json()
        for video in (waiting, running):
            first = client.delete(f"/api/videos/{video['id']}")
            wait_video(client, video["id"], states=("cancelled",))
            second = client.delete(f"/api/videos/{video['id']}")
            assert first.status_code == second.status_code == 200
            assert second.json()["state"] == "cancelled" and second.json()["id"] == video["id"]
            again = client.get(f"/api/videos/{video['id']}")
            assert again.status_code == 200 and again.json() == second.json()


class FlakyRay:
    """A painter in place of Ray's port: its frames are flat colours by index, and its first sequence fails after
    three frames, as Ray's does when a head goes away (Ray then backs off)."""

    def __init__(self):
        self.backoff = Backoff(first_s=0.2)
        self.asked: list[int] = []  # the first frame index of each sequence asked for

    def film(self, scene, path, width, height, params, temporal, start, previous, should_stop):
        shots = list(path.frames(start))
        self.asked.append(shots[0].index)
        for n, shot in enumerate(shots):
            if len(self.asked) == 1 and n == 3:
                self.backoff.failed("Ray went away")
                raise PainterFailed("Ray went away", self.backoff.wait_s())
            yield np.full((height, width, 3), 20 * shot.index, np.uint8), None


def test_a_video_on_ray_waits_out_a_ray_failure_and_goes_on_from_its_last_frame(tmp_path):
    settings = Settings(data=tmp_path, threads=1)
    workshop = Workshop(1, 1)
    painter = FlakyRay()
    with Store(tmp_path) as store:
        videos = Videos(settings, workshop, store, painter, Budget(settings.memory_bytes))
        try:
            job = videos.submit(make_scene(), parse_path(PATH).resolve(CAMERA), 32, 32, PaintParams(), None)
            messages = set()
            wait_until(lambda: messages.add(job.message) or job.state in FINISHED, pause=0.01)
            assert job.state == "done", job.message
            assert painter.asked == [0, 3]  # the three frames written were not asked for again
            assert "Ray went away; going on from frame 3 in 1 s" in messages
            with av.open(str(job.file)) as container:
                frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
            np.testing.assert_allclose([np.median(f) for f in frames], [20 * k for k in range(7)], atol=2)  # H.264
        finally:
            videos.close()
            workshop.close()


def test_an_equirect_stereo_path_becomes_a_360_video_that_players_recognise(server):
    """Keyframes with ``projection: "equirect"`` and ``stereo: "top-bottom"``: frames of both eyes (2H x H
    each, the left on top), and the MP4's spherical metadata as FFmpeg's reader finds it."""
    keyframes = [{**key, "projection": "equirect", "stereo": "top-bottom"} for key in PATH["keyframes"]]
    body = {"scene": "tiny", "path": {**PATH, "fps": 2, "keyframes": keyframes}, "width": 32, "height": 16}
    answer = server.post("/api/videos", json=body)
    assert answer.status_code == 202, answer.text
    assert wait_video(server, answer.json()["id"])["state"] == "done"
    video = server.get(f"/api/videos/{answer.json()['id']}/file").content
    with av.open(io.BytesIO(video)) as container:
        frame = next(container.decode(video=0))
        assert (frame.width, frame.height) == (32, 32)
        found = {sd.type.name: bytes(sd) for sd in frame.side_data}
    assert int.from_bytes(found["SPHERICAL"][:4], "little") == 0  # AV_SPHERICAL_EQUIRECTANGULAR
    assert int.from_bytes(found["STEREO3D"][:4], "little") == 2  # AV_STEREO3D_TOPBOTTOM
    refused = server.post("/api/videos", json={**body, "width": 32, "height": 24})
    assert "width must be 2 x height" in one_line(refused, 422)


def test_a_kept_job_keeps_its_cameras_whole():
    """What the store keeps of a path gives back the same cameras, a panorama's projection, stereo and ipd
    among them (a job resumed after a restart paints what was asked)."""
    keyframes = [{**key, "projection": "equirect", "stereo": "side-by-side", "ipd": 0.1} for key in PATH["keyframes"]]
    path = parse_path({**PATH, "keyframes": keyframes}).resolve(CAMERA)
    again = parse_path(path_spec(path)).resolve(CAMERA.moved(fov=30))
    assert again.cameras == path.cameras and again.times == path.times


def test_a_video_waits_for_the_memory_others_hold_and_one_that_never_fits_is_refused(tmp_path):
    """A film holds its painting's memory while it paints (memory.py): held by a walk-through, the film waits and
    says why, then paints once it is given back; a film larger than the whole budget is refused at the door."""
    settings = Settings(data=tmp_path, threads=1)
    workshop = Workshop(1, 1)
    path = parse_path(PATH).resolve(CAMERA)
    need = film_bytes(32, 32, path, PaintParams(), None)
    memory = Budget(need + need // 2)  # room for this film, not for it beside a walk as large
    with Store(tmp_path) as store:
        videos = Videos(settings, workshop, store, LocalPainter(workshop), memory)
        try:
            memory.reserve("a walk", need, (32, 32), "a walk-through")
            job = videos.submit(make_scene(), path, 32, 32, PaintParams(), None)
            wait_until(lambda: "of memory" in job.message or job.state not in ("queued", "running"), pause=0.01)
            assert job.message.startswith("this video of 32x32 pixels needs") and job.done_frames == 0
            assert memory.held(("video", job.id)) == 0
            memory.release("a walk")
            wait_until(lambda: job.state in FINISHED, pause=0.01)
            assert job.state == "done" and job.message.startswith("7 frames"), job.message
            assert memory.used == 0  # given back
            with pytest.raises(Refusal) as refused:
                videos.submit(make_scene(), path, 64, 64, PaintParams(), None)  # four times the bytes
            assert refused.value.status == 422 and "RCP_MEMORY_BYTES" in refused.value.message
        finally:
            videos.close()
            workshop.close()
