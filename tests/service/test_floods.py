"""Floods of a walk's messages against a real server: ``move`` and ``pick`` from six sockets at once leave a
good walker at least 80% of its frames (the newest of each waits, one is answered at a time), and a socket
past the message rate gets one error, then a close 1008 with the reason."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest
from helpers.servers import BackgroundServer
from helpers.wire import Walk
from websockets.exceptions import ConnectionClosed

FLOODERS = 6
MESSAGES = 2000  # of each kind, per flooding socket
WINDOW_S = 8.0  # frames are counted over this long, alone and then under the flood

FLOOD = """
import json, sys, threading, time
from websockets.sync.client import connect
url, count, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
def drain(ws):
    try:
        while True:
            ws.recv()
    except Exception:  # closed: the flood is over
        pass
def flood():
    with connect(url, max_size=None) as ws:
        threading.Thread(target=drain, args=(ws,), daemon=True).start()
        ws.send(json.dumps({"type": "hello", "scene": "default", "width": 32, "height": 18}))
        end = time.monotonic() + seconds
        for k in range(count):
            if time.monotonic() > end:
                break
            ws.send(json.dumps({"type": "move", "id": k, "eye": [0, 1.6, 3], "delta": [0.01, 0, -0.01]}))
            ws.send(json.dumps({"type": "pick", "x": k % 32, "y": k % 18}))
threads = [threading.Thread(target=flood) for _ in range(int(sys.argv[4]))]
[t.start() for t in threads]
[t.join() for t in threads]
"""


def frames_within(walk: Walk, seconds: float) -> int:
    """Frames the walk receives within ``seconds`` (its JPEGs read too)."""
    count, end = 0, time.monotonic() + seconds
    while time.monotonic() < end:
        if walk.next()["type"] == "frame":
            walk.ws.recv(30)
            count += 1
    return count


def test_six_sockets_of_moves_and_picks_leave_a_good_walker_its_frames():
    with BackgroundServer(max_messages_per_s=1e6, max_sessions=16) as server:  # no rate: only the newest wins
        walk = Walk(server)
        try:
            walk.send(type="hello", scene="sea", width=64, height=36)
            walk.send(type="mode", animate=True)  # the waves move: frames as fast as it can paint
            assert walk.next()["type"] == "ready"
            frames_within(walk, 2.0)  # warmed up
            alone = frames_within(walk, WINDOW_S)
            flood = subprocess.Popen(
                [sys.executable, "-c", FLOOD, server.ws_url, str(MESSAGES), str(WINDOW_S + 4), str(FLOODERS)]
            )
            try:
                time.sleep(1.0)  # the flooders connected and sending
                flooded = frames_within(walk, WINDOW_S)
            finally:
                flood.kill()
                flood.wait()
            print(f"frames alone {alone}, under the flood {flooded}")
            assert alone >= 4 and flooded >= 0.8 * alone, (alone, flooded)
        finally:
            walk.close()


def test_a_socket_past_the_message_rate_gets_one_error_and_a_close_with_the_reason():
    reason = "more than 50 messages a second (RCP_MAX_MESSAGES_PER_S)"
    with BackgroundServer(max_messages_per_s=50) as server:
        walk = Walk(server)
        try:
            walk.send(type="hello", scene="default", width=64, height=36)
            for k in range(400):  # 200 at once are allowed (four seconds' worth)
                try:
                    walk.send(type="move", id=k, eye=[0, 1.6, 3], delta=[0.01, 0, 0])
                except ConnectionClosed:
                    break
            errors = []
            with pytest.raises(ConnectionClosed) as closed:
                while True:
                    raw = walk.ws.recv(30)
                    if isinstance(raw, str) and (message := json.loads(raw))["type"] == "error":
                        errors.append(message["message"])
            assert errors == [reason]
            assert (closed.value.rcvd.code, closed.value.rcvd.reason) == (1008, reason)
        finally:
            walk.close()
