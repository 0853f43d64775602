"""A video job never starves a walk-through: on a real server with its own threads, a walk steps through a
scene and every step is answered down to its final, refined frame while a long video paints on the same
shared tile pool, and the video goes on painting throughout (the pool serves both in turns)."""

from __future__ import annotations

import httpx
import pytest
from helpers.scenes import SPINNING_BOX
from helpers.servers import FINISHED, BackgroundServer
from helpers.waits import wait_until

# a video far longer than the walk (6001 frames), of a modest size: it is still painting when the walk ends
VIDEO = {
    "scene": "tiny",
    "width": 128,
    "height": 96,
    "path": {
        "fps": 60,
        "keyframes": [
            {"t": 0, "eye": [0, 1, 4], "look_at": [0, 0.5, 0]},
            {"t": 100, "eye": [3, 1.5, 2], "look_at": [0, 0.5, 0]},
        ],
    },
}
CANVAS = (160, 120)
STEPS = 8
DEADLINE_S = 60.0  # against a hang, not a timing


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    scenes = tmp_path_factory.mktemp("scenes")
    (scenes / "tiny.toml").write_text(SPINNING_BOX)
    with BackgroundServer(scenes=scenes, settle_ms=80) as live:
        yield live


def video_status(client: httpx.Client, video_id: str) -> dict:
    answer = client.get(f"/api/videos/{video_id}")
    assert answer.status_code == 200, answer.text
    return answer.json()


def test_a_walk_is_answered_step_by_step_while_a_video_paints(server, walk_to):
    with httpx.Client(base_url=server.url, timeout=30) as client:
        created = client.post("/api/videos", json=VIDEO)
        assert created.status_code == 202, created.text
        video_id = created.json()["id"]
        started = wait_until(
            lambda: video_status(client, video_id), lambda s: s["done_frames"] or s["state"] in FINISHED
        )
        assert started["state"] in ("queued", "running"), started  # a first frame painted, the rest to come

        walk = walk_to(server)
        walk.send(type="hello", scene="tiny", width=CANVAS[0], height=CANVAS[1])
        assert walk.next()["type"] == "ready"
        walk.until_final()
        progress = [video_status(client, video_id)["done_frames"]]
        for k in range(STEPS):
            walk.send(type="camera", eye=[0.2 * k, 1.0, 4.0], look_at=[0.0, 0.5, 0.0], id=k)
            frames = [meta for meta, _ in walk.until_final(timeout=DEADLINE_S)]
            # every frame after the step shows it, the last one refined at full size
            assert {meta["camera_id"] for meta in frames} == {k}
            last = frames[-1]
            assert last["phase"] == "refine" and (last["width"], last["height"]) == CANVAS and last["spp"] >= 4
            status = video_status(client, video_id)
            assert status["state"] == "running", status  # the step was answered before the video finished
            progress.append(status["done_frames"])

        # both made progress: the video painted frames in the first half of the walk and in the second
        half = STEPS // 2
        assert progress[0] < progress[half] < progress[-1] < status["frames"], progress
        stopped = client.delete(f"/api/videos/{video_id}").json()
        assert stopped["state"] in ("running", "cancelled") and stopped["done_frames"] < stopped["frames"]
        wait_until(lambda: video_status(client, video_id)["state"] != "running")
        assert video_status(client, video_id)["state"] == "cancelled"
