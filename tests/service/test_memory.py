"""Memory as a resource the server admits (``service/memory.py``): the budget's account alone; on a real server,
walks and renders refused in one line once the paintings' declared bytes pass ``RCP_MEMORY_BYTES``, and the
resident memory of a real ``rcp serve`` back near where it was once walks of a million pixels close."""

from __future__ import annotations

import json
import re
import threading
import time

import httpx
import pytest
from helpers.servers import BackgroundServer, rcp_serve
from helpers.wire import Walk
from websockets.sync.client import connect

from rcp_server.scene.scenefile import load_scene
from rcp_server.service.memory import MB, RETRY_AFTER_S, WALK_KEEPS, Budget, NoRoom, painting_bytes

# ---- the account alone ----


def test_a_budget_holds_each_holders_bytes_once_and_refuses_past_its_total():
    budget = Budget(100)
    budget.reserve("a", 60, (6, 10), "a walk")
    budget.reserve("a", 40, (4, 10), "a walk")  # in place of what it held
    budget.reserve("b", 60, (6, 10), "a walk")
    assert budget.used == 100 and budget.held("a") == 40
    with pytest.raises(NoRoom) as now:
        budget.reserve("c", 1, (1, 1), "a walk")
    assert now.value.retry_after == RETRY_AFTER_S and now.value.status == 503
    with pytest.raises(NoRoom) as never:
        budget.reserve("c", 400, (20, 10), "a walk")
    assert never.value.retry_after is None and never.value.status == 422
    assert "at most 10x5 would fit" in str(never.value)  # half the side: a quarter of the bytes
    with pytest.raises(NoRoom):
        budget.reserve("a", 41, (4, 10), "a walk")  # growing past the room: it keeps what it held
    assert budget.held("a") == 40
    assert budget.release("a") == 40 and budget.release("a") == 0 and budget.used == 60
    with budget.reserved(40, (4, 10), "a render"):
        assert budget.used == 100
    assert budget.used == 60


# ---- on a real server ----

PER_PIXEL = painting_bytes(load_scene("default").paint, 1, 1, kept=WALK_KEEPS)
BUDGET = 16 * MB  # the least RCP_MEMORY_BYTES takes
SMALL = (640, 360)  # two fit in the budget, not three
LARGE = (1280, 720)  # never fits


def test_walks_and_renders_past_the_memory_budget_are_refused_in_one_line():
    assert 2 * SMALL[0] * SMALL[1] * PER_PIXEL <= BUDGET < 3 * SMALL[0] * SMALL[1] * PER_PIXEL
    assert LARGE[0] * LARGE[1] * PER_PIXEL > BUDGET
    with BackgroundServer(memory_bytes=BUDGET, settle_ms=50) as server:
        never = hello(server, *LARGE)
        assert never["type"] == "error" and "RCP_MEMORY_BYTES" in never["message"], never
        offered = re.search(r"at most (\d+)x(\d+) would fit$", never["message"])
        assert offered, never
        first = Walk(server)
        first.send(type="hello", scene="default", width=int(offered[1]), height=int(offered[2]))
        assert first.next()["type"] == "ready"  # what it offers fits
        first.close()

        walks = [Walk(server) for _ in range(2)]
        for walk in walks:
            walk.send(type="hello", scene="default", width=SMALL[0], height=SMALL[1])
            assert walk.next()["type"] == "ready"
        refused = until_said(server, *SMALL)  # the first walk's share may take a moment to go
        assert refused["type"] == "error" and f"try again in {RETRY_AFTER_S} s" in refused["message"], refused
        assert "\n" not in refused["message"] and "RCP_MEMORY_BYTES" in refused["message"]

        # a walk that asks to grow past the room is told so, and walks on at its size
        walks[0].send(type="view", width=LARGE[0], height=LARGE[1])
        while isinstance(said := walks[0].ws.recv(30), bytes) or json.loads(said)["type"] != "error":
            pass
        assert "RCP_MEMORY_BYTES" in json.loads(said)["message"]
        assert walks[0].until_final()[-1][1].shape[:2] == (SMALL[1], SMALL[0])

        # renders: 503 and Retry-After while the walks hold the room, 422 for one that never fits
        render = {"scene": "default", "width": 600, "height": 400}
        busy = httpx.post(f"{server.url}/api/render", json=render, timeout=60)
        assert busy.status_code == 503 and busy.headers["retry-after"] == str(RETRY_AFTER_S), busy.text
        assert "RCP_MEMORY_BYTES" in busy.json()["detail"]
        huge = httpx.post(f"{server.url}/api/render", json={**render, "width": 1600, "height": 900}, timeout=60)
        assert huge.status_code == 422 and "RCP_MEMORY_BYTES" in huge.json()["detail"]

        # once a walk closes, its share is free: the walk refused before now starts
        walks[1].close()
        assert until_said(server, *SMALL, wanted="ready")["type"] == "ready"
        assert httpx.post(f"{server.url}/api/render", json=render, timeout=120).status_code == 200
        walks[0].close()


def hello(server, width: int, height: int) -> dict:
    """The first answer to a walk's hello at ``width x height`` (the walk then closes)."""
    with connect(server.ws_url, open_timeout=30) as ws:
        ws.send(json.dumps({"type": "hello", "scene": "default", "width": width, "height": height}))
        return json.loads(ws.recv(30))


def until_said(server, width: int, height: int, wanted: str = "error") -> dict:
    """Hello until the answer is ``wanted`` (a closed walk's share goes as the server sees it close)."""
    for _ in range(100):
        answer = hello(server, width, height)
        if answer["type"] == wanted:
            return answer
        time.sleep(0.1)
    return answer


MARGIN_MB = 60  # resident memory after the walks closed: at most this over where it was before them
WALKS = 2
WIDTH, HEIGHT = 1333, 750  # a million pixels


def walk_to_final(url: str, width: int, height: int) -> None:
    """A walk that paints until its refinement's last frame at full size, then closes."""
    with connect(url, max_size=None, open_timeout=60) as ws:
        ws.send(json.dumps({"type": "hello", "scene": "default", "width": width, "height": height}))
        to_final(ws)


def test_resident_memory_comes_back_after_walks_of_a_million_pixels_close(tmp_path):
    with rcp_serve(tmp_path) as served:
        walk_to_final(served.ws_url, 320, 180)  # what the first walk leaves for good (compiled code, caches)
        time.sleep(1)
        before = served.sample().rss_mb
        peak, done = [before], threading.Event()

        def watch() -> None:
            while not done.is_set():
                peak.append(served.sample().rss_mb)
                time.sleep(0.1)

        watcher = threading.Thread(target=watch)
        walkers = [threading.Thread(target=walk_to_final, args=(served.ws_url, WIDTH, HEIGHT)) for _ in range(WALKS)]
        watcher.start()
        for walker in walkers:
            walker.start()
        for walker in walkers:
            walker.join()
        done.set()
        watcher.join()
        deadline = time.monotonic() + 60  # the last paintings stop at their next iteration, then memory goes back
        while (after := served.sample().rss_mb) > before + MARGIN_MB and time.monotonic() < deadline:
            time.sleep(0.5)
        figures = f"{before:.0f} MB before, {max(peak):.0f} MB at the peak, {after:.0f} MB after"
        print(figures)
        assert max(peak) > before + 2 * MARGIN_MB, figures  # the walks did take memory
        assert after <= before + MARGIN_MB, figures


def test_a_walk_that_shrinks_gives_its_larger_buffers_back(tmp_path):
    """One walk, open throughout: small, then 1920x1080, then small again; its memory goes back near where the
    small walk had it."""
    with rcp_serve(tmp_path) as served, connect(served.ws_url, max_size=None, open_timeout=60) as ws:
        ws.send(json.dumps({"type": "hello", "scene": "default", "width": 320, "height": 180}))
        to_final(ws)
        time.sleep(1)
        before = served.sample().rss_mb
        ws.send(json.dumps({"type": "view", "width": 1920, "height": 1080}))
        to_final(ws)
        large = served.sample().rss_mb
        ws.send(json.dumps({"type": "view", "width": 320, "height": 180}))
        to_final(ws)
        deadline = time.monotonic() + 60
        while (after := served.sample().rss_mb) > before + MARGIN_MB and time.monotonic() < deadline:
            time.sleep(0.5)
        figures = f"{before:.0f} MB small, {large:.0f} MB large, {after:.0f} MB small again"
        print(figures)
        assert large > before + 2 * MARGIN_MB and after <= before + MARGIN_MB, figures


def to_final(ws) -> dict:
    """Reads a walk's messages up to its refinement's last frame; that frame's description."""
    while True:
        message = ws.recv(300)
        if isinstance(message, bytes):
            continue
        said = json.loads(message)
        assert said["type"] != "error", said
        if said["type"] == "frame" and said["final"]:
            ws.recv(300)
            return said
