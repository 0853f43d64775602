"""The data folder is untrusted input: a real server on loopback started on a folder tampered with between two
runs (records naming ``../`` paths, of the wrong type, settings that are not JSON, symbolic links in place of
files and folders, a damaged frame, FIFOs in place of stored arrays) starts in bounded time, skips each bad row
in one log line naming the row and the folder, serves and writes nothing through a link, and leaves everything
outside the folder as it was."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from helpers import uploads as files
from helpers.scenes import SPINNING_BOX
from helpers.servers import BackgroundServer, free_port, job_status, rcp_environment

from rcp_server.camera.camera import Camera
from rcp_server.media.camerapath import parse_path
from rcp_server.service.store import DataFolderError, Store, UploadRecord, VideoRecord, VideoSettings, new_video_id
from rcp_server.service.videos import path_spec
from rcp_server.settings.params import PaintParams

SCENE_CAMERA = Camera((0.0, 1.0, 4.0), (0.0, 0.5, 0.0))
PATH = {
    "fps": 2,
    "keyframes": [
        {"t": 0, "eye": [0, 1, 4], "look_at": [0, 0.5, 0]},
        {"t": 1, "eye": [1, 1, 4], "look_at": [0, 0.5, 0]},
    ],
}
FRAMES = 3
SECRET = b"what lies outside the data folder\n"
NOT_JSON = "Expecting property name enclosed in double quotes"


@pytest.fixture
def scenes(tmp_path) -> Path:
    folder = tmp_path / "scenes"
    folder.mkdir()
    (folder / "tiny.toml").write_text(SPINNING_BOX)
    return folder


@pytest.fixture
def outside(tmp_path) -> Path:
    """A folder beside the data folder, with a file and a folder in it: nothing of it may change."""
    folder = tmp_path / "outside"
    (folder / "victim").mkdir(parents=True)
    (folder / "victim" / "keep.txt").write_bytes(SECRET)
    (folder / "secret.txt").write_bytes(SECRET)
    return folder


def intact(outside: Path) -> dict[str, bytes]:
    return {str(p.relative_to(outside)): p.read_bytes() for p in sorted(outside.rglob("*")) if p.is_file()}


def video_record(video_id: str, state: str = "queued", temporal: int | None = None, **changes) -> VideoRecord:
    path = parse_path(path_spec(parse_path(PATH).resolve(SCENE_CAMERA)))  # written out in full, as a job keeps it
    settings = VideoSettings(path=path, width=32, height=32, params=PaintParams().settings(), temporal=temporal)
    values = {
        "id": video_id,
        "scene": "tiny",
        "settings": settings,
        "frames": FRAMES,
        "state": state,
        "done_frames": 0,
        "message": "",
        "created": time.time(),
        "finished": None,
        "bytes": 0,
    }
    return VideoRecord(**{**values, **changes})


def insert(data: Path, table: str, row: tuple) -> None:
    """A row written straight into the records, as whoever tampered with the folder would."""
    with sqlite3.connect(data / "rcp.sqlite") as db:
        db.execute(f"INSERT INTO {table} VALUES ({', '.join('?' for _ in row)})", row)


def skipped(caplog, data: Path) -> list[str]:
    return sorted(m for m in caplog.messages if m.startswith(f"data folder {data}: "))


def wait_for(client: httpx.Client, video_id: str, until) -> dict:
    return job_status(client, f"/api/videos/{video_id}", until)


def test_records_naming_paths_of_the_wrong_type_or_not_json_are_skipped_in_one_line(tmp_path, scenes, outside, caplog):
    """Defects 4, 7 and 8: an upload or video record named ``../../outside/victim`` deletes and writes nothing
    outside; a text weight and settings that are not JSON no longer stop start-up; each bad row is one line
    naming its row and the folder, and the good records beside them are served."""
    caplog.set_level("INFO", "rcp.service")
    data = tmp_path / "data"
    with BackgroundServer(scenes=scenes, data=data) as live, httpx.Client(base_url=live.url, timeout=60) as client:
        upload = client.post("/api/scenes", files={"file": ("Box.glb", files.glb())}).json()["name"]
        good = client.post("/api/videos", json={"scene": "tiny", "path": PATH, "width": 32, "height": 32}).json()
        assert wait_for(client, good["id"], lambda s: s["state"] == "done")["state"] == "done"
    before = intact(outside)
    name = "../../outside/victim"
    now = time.time()
    insert(data, "uploads", (name, "x", None, 1, 1, 0.0, 0.0))  # idle: the old server removed it at start-up
    insert(data, "uploads", ("u-" + "a" * 22, "x", None, 1, "heavy", now, now))  # a text weight
    settings = video_record(new_video_id()).settings.model_dump_json()
    insert(data, "videos", (name, "tiny", settings, FRAMES, "queued", 0, "", now, None, 0))
    insert(data, "videos", (new_video_id(), "tiny", "{not json", FRAMES, "queued", 0, "", now + 1, None, 0))
    insert(data, "videos", (new_video_id(), "tiny", settings, "many", "queued", 0, "", now + 2, None, 0))
    with BackgroundServer(scenes=scenes, data=data) as live, httpx.Client(base_url=live.url, timeout=60) as client:
        assert client.get(f"/api/scenes/{upload}").status_code == 200
        assert client.get(f"/api/videos/{good['id']}/file").status_code == 200
        assert client.post("/api/render", json={"scene": upload, "width": 16, "height": 16}).status_code == 200
    lines = skipped(caplog, data)
    assert len(lines) == 5, lines
    assert lines[0].startswith(f"data folder {data}: uploads row 2 skipped: name: String should match pattern")
    assert lines[1].startswith(f"data folder {data}: uploads row 3 skipped: weight: Input should be a valid integer")
    assert lines[2].startswith(f"data folder {data}: videos row 2 skipped: id: String should match pattern")
    assert lines[3] == f"data folder {data}: videos row 3 skipped: its settings are not JSON ({NOT_JSON})"
    assert lines[4].startswith(f"data folder {data}: videos row 4 skipped: frames: Input should be a valid integer")
    assert all("\n" not in line for line in lines)
    assert intact(outside) == before and (outside / "victim").is_dir()


def test_nothing_is_served_written_or_truncated_through_a_symbolic_link(tmp_path, scenes, outside, caplog):
    """Defects 5 and 6: a finished video whose file is a link is not served, wherever it points; a job whose
    frames folder is a link writes nothing through it; a ``lock`` that is a link stops the server in one line
    (exit 2), and what it points to is not truncated."""
    caplog.set_level("INFO", "rcp.service")
    data = tmp_path / "data"
    with Store(data) as store:
        served = new_video_id()
        store.add_video(video_record(served, "done", finished=time.time(), bytes=len(SECRET)))
        os.symlink(outside / "secret.txt", store.video_file(served))
        painted = new_video_id()
        store.add_video(video_record(painted))
        os.symlink(outside / "victim", store.frames_dir(painted))
    before = intact(outside)
    with BackgroundServer(scenes=scenes, data=data) as live, httpx.Client(base_url=live.url, timeout=60) as client:
        answer = client.get(f"/api/videos/{served}/file")
        assert answer.status_code == 409 and SECRET not in answer.content
        status = wait_for(client, painted, lambda s: s["state"] not in ("queued", "running"))
        assert (
            status["state"] == "failed"
            and status["message"] == f"{painted} in the data folder is not a folder of its own"
        )
    assert intact(outside) == before
    (data / "lock").unlink()
    os.symlink(outside / "secret.txt", data / "lock")
    started = subprocess.run(
        [sys.executable, "-m", "rcp_server.cli", "serve", "--port", str(free_port())],
        env=rcp_environment(data=str(data), scenes=str(scenes)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert started.returncode == 2
    assert started.stderr.strip().splitlines() == [
        f"rcp: error: cannot use the data folder {data}: its lock: Too many levels of symbolic links"
    ]
    assert intact(outside) == before


def test_a_damaged_kept_frame_fails_its_job_without_naming_the_servers_paths(tmp_path, scenes):
    """Defect 9: a resumed job whose kept frame is damaged fails, saying which frame, not where it lies."""
    data = tmp_path / "data"
    with Store(data) as store:
        job = new_video_id()
        store.add_video(video_record(job, "running", done_frames=FRAMES))
        frames = store.frames_dir(job)
        frames.mkdir()
        with BackgroundServer(scenes=scenes, data=data / "elsewhere") as live:  # any good frames will do
            good = httpx.post(f"{live.url}/api/render", json={"scene": "tiny", "width": 32, "height": 32}).content
    for k in range(FRAMES):
        (frames / f"frame_{k:06d}.png").write_bytes(good if k != 1 else b"\x89PNG\r\n\x1a\n damaged")
    with BackgroundServer(scenes=scenes, data=data) as live, httpx.Client(base_url=live.url, timeout=60) as client:
        status = wait_for(client, job, lambda s: s["state"] not in ("queued", "running"))
    assert status["state"] == "failed"
    assert status["message"] == "frame 1 kept in the data folder is damaged; ask for the video again"


def test_fifos_in_place_of_stored_arrays_and_frames_do_not_hang_start_up(tmp_path, scenes, caplog):
    """Defect 10: a FIFO in place of an upload's arrays, of a temporal job's state and of a kept frame: the
    server starts in bounded time, removes the upload in one line, and paints the job from its first frame."""
    caplog.set_level("INFO", "rcp.service")
    data = tmp_path / "data"
    name = "u-" + "b" * 22
    with Store(data) as store:
        now = time.time()
        record = UploadRecord(name=name, title="x", owner=None, file_bytes=1, weight=1, created=now, used=now)
        store.add_upload(record)
        store.upload_dir(name).mkdir()
        os.mkfifo(store.upload_dir(name) / "parts.npz")
        job = new_video_id()
        store.add_video(video_record(job, "running", temporal=1, done_frames=1))
        store.frames_dir(job).mkdir()
        os.mkfifo(store.frames_dir(job) / "frame_000000.png")
        os.mkfifo(store.frames_dir(job) / "state.npz")
    # it starts at all (a FIFO opened for reading would wait for a writer for ever), and answers
    with BackgroundServer(scenes=scenes, data=data) as live, httpx.Client(base_url=live.url, timeout=60) as client:
        assert client.get(f"/api/scenes/{name}").status_code == 404
        status = wait_for(client, job, lambda s: s["state"] not in ("queued", "running"))
        assert status == {
            "id": job,
            "state": "done",
            "frames": FRAMES,
            "done_frames": FRAMES,
            "message": status["message"],
        }
    assert f"upload {name} removed: it no longer loads (parts.npz in the data folder is not a regular file)" in (
        caplog.messages
    )


@pytest.mark.parametrize("name", ["rcp.sqlite", "rcp.sqlite-wal"])
def test_records_that_are_a_link_or_a_fifo_stop_the_server_in_one_line(tmp_path, outside, name):
    """SQLite opens its files by name: a link in their place would be written through, a FIFO would block."""
    data = tmp_path / "data"
    Store(data).close()
    before = intact(outside)
    for make in (lambda p: os.symlink(outside / "secret.txt", p), os.mkfifo):
        (data / name).unlink(missing_ok=True)
        make(data / name)
        with pytest.raises(DataFolderError) as refused:
            Store(data)
        assert str(refused.value) == f"cannot use the records in {data}: {name} is not a regular file"
        assert intact(outside) == before
