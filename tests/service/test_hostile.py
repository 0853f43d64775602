"""Hostile input, load and faults against a real server on loopback: every refusal is a clear 4xx (or a 503
with Retry-After), nothing hangs, nothing leaks, and everyone else goes on being served."""

from __future__ import annotations

import json
import logging
import signal
import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest
from helpers.servers import BackgroundServer, rcp_serve
from helpers.waits import WAIT_S, wait_until
from helpers.wire import Walk, decode
from websockets.exceptions import ConnectionClosed

BIG = {"scene": "default", "width": 1280, "height": 720, "paint": {"spp": 8}}  # seconds of work on 2 cores


def health(server, **headers) -> dict:
    return httpx.get(f"{server.url}/api/health", headers=headers, timeout=10).json()


def post(server, body, **options) -> httpx.Response:
    return httpx.post(f"{server.url}/api/render", json=body, timeout=120, **options)


def raw_http(server, request: bytes) -> bytes:
    """Bytes on the wire, for requests an HTTP library would tidy up first (dot segments, bad lengths)."""
    with socket.create_connection(("127.0.0.1", server.settings.port), timeout=10) as sock:
        sock.sendall(request)
        response = b""
        while chunk := sock.recv(65536):
            response += chunk
    return response


@pytest.fixture(scope="module")
def tight():
    """A server with small limits: one render at a time and one waiting, 2^24 rays per painting (2-3 s)."""
    settings = dict(settle_ms=50, max_renders=1, max_waiting=1, max_work=1 << 24, max_message_bytes=1024)
    with BackgroundServer(**settings) as server:
        yield server


# ---- limits ----


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ({"scene": "default", "width": 4096, "height": 4096}, "pixels"),
        ({"scene": "default", "width": 1024, "height": 1024, "paint": {"spp": 4}}, "rays"),
        ({"scene": "default", "width": 1024, "height": 1024, "paint": {"iterations": 64}}, "rays"),
        ({"scene": "default", "width": 100000, "height": 100000}, "width"),
        ({"scene": "default", "paint": {"spp": 1000000}}, "spp"),
    ],
)
def test_requests_over_a_limit_get_422_with_the_limit(tight, body, says):
    response = post(tight, body)
    assert response.status_code == 422 and says in response.text, response.text


def test_a_body_over_the_size_limit_gets_413(tight):
    padding = {"scene": "default", "camera": {"eye": [0, 1, 2], "look_at": [0, 0, 0]}, "x": "y" * 70_000}
    response = post(tight, padding)
    assert response.status_code == 413
    # a lying Content-Length, and a chunked body with none, are cut off at the limit too
    head = b"POST /api/render HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\nConnection: close\r\n"
    lying = raw_http(tight, head + b"Content-Length: 10000000\r\n\r\n" + b"{" * 70_000)
    assert lying.startswith(b"HTTP/1.1 413")
    chunk = b"{" * 40_000
    chunked = head + b"Transfer-Encoding: chunked\r\n\r\n" + (b"%x\r\n%s\r\n" % (len(chunk), chunk)) * 3 + b"0\r\n\r\n"
    assert raw_http(tight, chunked).startswith(b"HTTP/1.1 413")
    assert health(tight)["status"] == "ok"


def test_a_full_house_gets_503_with_retry_after_and_health_still_answers(tight):
    body = {"scene": "default", "width": 1024, "height": 1024, "paint": {"spp": 2, "iterations": 8}}
    with httpx.Client(timeout=120) as http:
        results = []
        callers = [threading.Thread(target=lambda: results.append(post(tight, body))) for _ in range(2)]
        for caller in callers:
            caller.start()
        wait_until(lambda: health(tight)["renders"] == 2)  # one running, one waiting
        refused = http.post(f"{tight.url}/api/render", json=body)
        assert refused.status_code == 503 and "busy" in refused.json()["detail"]
        assert int(refused.headers["retry-after"]) >= 1
        assert http.get(f"{tight.url}/api/health").status_code == 200
        for caller in callers:
            caller.join(120)
    assert [r.status_code for r in results] == [200, 200]


def test_a_render_past_the_time_limit_gets_503_and_stops_painting():
    with BackgroundServer(render_timeout_s=0.5) as server:
        response = post(server, BIG)
        # the 503 is the painting abandoned at a tile: one painted to its end is answered with its image, late
        assert response.status_code == 503 and "0.5 s limit" in response.json()["detail"]
        assert "retry-after" in response.headers
        assert health(server)["painting"] == 0  # and stopped: it had ended before the answer was sent


def test_a_caller_that_hangs_up_mid_render_stops_its_painting(tight, caplog):
    caplog.set_level("INFO", "rcp.service")
    body = json.dumps(
        {"scene": "default", "width": 1024, "height": 1024, "paint": {"spp": 2, "iterations": 8}}
    ).encode()
    request = b"POST /api/render HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
    request += b"Content-Length: %d\r\n\r\n%s" % (len(body), body)
    with socket.create_connection(("127.0.0.1", tight.settings.port), timeout=10) as sock:
        sock.sendall(request)
        wait_until(lambda: health(tight)["painting"] == 1)  # the render started
    wait_until(lambda: health(tight)["painting"] == 0 and health(tight)["renders"] == 0)
    # stopped at a tile, not painted to its end: the server says so
    assert "a render stopped at its next tile: its caller left" in caplog.messages


# ---- validation at the edge ----


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ('{"scene": "default", "time": NaN}', "finite"),
        ('{"scene": "default", "time": Infinity}', "finite"),
        ('{"scene": "default", "camera": {"eye": [NaN, 0, 0], "look_at": [0, 0, 0]}}', "finite"),
        ('{"scene": "default", "camera": {"eye": [0, 0, 1e999], "look_at": [0, 0, 0]}}', "finite"),
        ('{"scene": "default", "paint": {"lambda_p": NaN}}', "lambda_p"),
        ('{"scene": "default", "camera": {"eye": [0, 0, 0], "look_at": [0, 0, 0]}}', "eye"),
        ('{"scene": "default", "camera": {"eye": [0, 0, 0], "look_at": [0, 0, -1], "up": [0, 0, 0]}}', "up"),
        ('{"scene": "default", "camera": {"eye": [0, 0, 0], "look_at": [0, 0, -1], "fov": 180}}', "fov"),
        ('{"scene": "default", "camera": {"eye": [0, 0, 0], "look_at": [0, 0, -1], "fov": 0}}', "fov"),
        ('{"scene": "default", "format": "gif"}', "format"),
        ('{"scene": "default", "paint": {"method": "magic"}}', "method"),
        ('{"scene": "default", "paint": {"edge": "fold"}}', "edge"),
        ('{"scene": "../../../etc/passwd"}', "pattern"),
        ('{"scene": "/etc/passwd"}', "pattern"),
        ('{"scene": "default\\u0000"}', "pattern"),
        ('{"scene": "default\\n"}', "pattern"),
        ('{"scene": ["default"]}', "string"),
        ('{"scene": "default"', "JSON"),
        ("[" * 10_000 + "]" * 10_000, "parsing the body"),  # 400: deeper than the JSON parser goes
        ("", "body"),
    ],
    ids=lambda value: value[:40] if isinstance(value, str) else None,
)
def test_malformed_renders_get_422_never_5xx(tight, body, says):
    response = httpx.post(f"{tight.url}/api/render", content=body, headers={"content-type": "application/json"})
    assert response.status_code in (400, 422) and says in response.text, (response.status_code, response.text)
    assert "Traceback" not in response.text


@pytest.mark.parametrize(
    "path",
    [
        b"/../pyproject.toml",
        b"/%2e%2e/pyproject.toml",
        b"/..%2fpyproject.toml",
        b"/%2e%2e%2f%2e%2e%2fetc%2fpasswd",
        b"/..\\pyproject.toml",
        b"//etc/passwd",
        b"/index.html%00.png",
        b"/scenes/default.toml",
    ],
)
def test_static_files_come_only_from_the_client_folder(tight, path):
    response = raw_http(tight, b"GET %s HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n" % path)
    status = int(response.split(b" ", 2)[1])
    assert status in (400, 404), response[:200]
    assert b"[project]" not in response and b"root:" not in response and b"[camera]" not in response


# ---- the WebSocket ----


def test_hostile_messages_get_errors_and_the_walk_goes_on(tight, walk_to):
    walk = walk_to(tight)
    walk.send(type="hello", scene="sky", width=32, height=18)
    assert walk.next()["type"] == "ready"
    walk.until_final()  # nothing more comes until something changes
    hostile = [
        json.dumps({"type": "camera", "eye": [0, 0, 0], "look_at": [0, 0, -1], "pad": "x" * 2000}),  # over 1 KiB
        "[" * 500 + "]" * 500,
        '{"type": "camera", "eye": [NaN, 0, 0], "look_at": [0, 0, -1]}',
        '{"type": "camera", "eye": [0, 0, 0], "look_at": [0, 0, 0]}',
        '{"type": "view", "width": 2048, "height": 2048}',  # over the work limit
        '{"type": "paint", "lambda_p": 1e308}',
        '{"type": "hello", "scene": "../sky"}',
        '{"type": "teleport"}',
        "not json",
        "",
    ]
    for text in hostile:
        walk.ws.send(text)
        reply = walk.next()
        assert reply["type"] == "error" and "Traceback" not in reply["message"], (text[:40], reply)
    walk.send(type="camera", eye=[0, 0, 0], look_at=[0, 0.2, -1], id=7)
    meta, image = walk.frame()
    assert meta["camera_id"] == 7 and image.shape == (meta["height"], meta["width"], 3)


def test_a_message_past_the_transport_limit_closes_with_1009(tight, walk_to):
    walk = walk_to(tight)
    walk.ws.send("x" * (64 * 1024 + 1))
    with pytest.raises(ConnectionClosed) as closed:
        walk.next(10)
    assert closed.value.rcvd.code == 1009
    assert health(tight)["status"] == "ok"


def test_a_flood_of_camera_messages_is_coalesced(tight, walk_to):
    walk = walk_to(tight)
    walk.send(type="hello", scene="default", width=64, height=36)
    walk.next()
    for k in range(3000):
        walk.send(type="camera", eye=[0, 2, 8 - k * 0.001], look_at=[0, 1, 0], id=k)
    frames = walk.until_final()
    assert frames[-1][0]["camera_id"] == 2999
    assert len(frames) < 300  # painted as fast as it could, always the newest camera


def test_a_client_that_stops_reading_is_dropped_and_never_buffered(walk_to):
    with BackgroundServer(settle_ms=50, send_timeout_s=2) as server:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # before connecting, or the kernel ignores it
        sock.connect(("127.0.0.1", server.settings.port))
        reader = walk_to(server, sock=sock, max_queue=1)  # reads nothing it is not asked for
        # walk frames go out at JPEG quality 70 at most: a large canvas, so they fill the buffers soon
        reader.send(type="hello", scene="sea", width=1920, height=1080, quality=100)
        # the waves move: a new frame as fast as it can paint (one iteration each, temporal)
        reader.send(type="mode", animate=True, temporal=True)
        other = walk_to(server)
        other.send(type="hello", scene="sky", width=32, height=18)
        other.next()
        (session,) = (s for s in server.app.state.service.sessions if s.scene.name == "sea")
        wait_until(lambda: session.outbox.dropped > 0)  # a frame dropped for the slow reader
        assert len(session.outbox.notes) <= session.outbox.notes.maxlen
        assert other.until_final()  # everyone else is served meanwhile
        wait_until(lambda: len(server.app.state.service.sessions) == 1)  # the slow reader let go
        wait_until(lambda: health(server)["painting"] == 0)  # its painting, of waves that never rest, stopped


def test_a_disconnect_mid_render_frees_the_session_and_its_painting(tight, walk_to):
    walk = walk_to(tight)
    walk.send(type="hello", scene="default", width=1024, height=512, quality=90)
    walk.next()
    wait_until(lambda: health(tight)["painting"] == 1)  # the painting started
    walk.ws.socket.close()  # no close handshake: the connection just drops
    wait_until(lambda: health(tight)["sessions"] == 0 and health(tight)["painting"] == 0)  # the session freed


# ---- access ----


def test_a_token_guards_rest_and_websocket_but_not_the_health_check(walk_to):
    with BackgroundServer(settle_ms=50, token="open sesame") as server:
        render = {"scene": "sky", "width": 16, "height": 16}
        assert post(server, render).status_code == 401
        refused = post(server, render, headers={"authorization": "Bearer open sesami"})
        assert refused.status_code == 401 and "needs a token" in refused.json()["detail"]
        assert refused.headers["www-authenticate"] == "Bearer"
        assert post(server, render, headers={"authorization": "Bearer open sesame"}).status_code == 200
        assert httpx.get(f"{server.url}/api/scenes", params={"token": "open sesame"}).status_code == 200
        assert httpx.get(f"{server.url}/api/scenes").status_code == 401
        assert health(server) == {"status": "ok"}  # the figures are for callers with the token
        assert "sessions" in health(server, authorization="Bearer open sesame")
        stranger = walk_to(server)
        assert "needs a token" in stranger.next()["message"]
        with pytest.raises(ConnectionClosed) as closed:
            stranger.next(10)
        assert closed.value.rcvd.code == 1008
        friend = walk_to(server, "?token=open%20sesame")
        friend.send(type="hello", scene="sky", width=16, height=16)
        assert friend.next()["type"] == "ready"
        schemes = httpx.get(f"{server.url}/openapi.json", params={"token": "open sesame"}).json()
        schemes = schemes["components"]["securitySchemes"]
        assert {s["type"] for s in schemes.values()} == {"http", "apiKey"}  # the docs say how to bring it


def test_cors_is_off_unless_configured_and_foreign_pages_cannot_walk(tight, walk_to):
    origin = {"origin": "http://evil.example"}
    response = httpx.get(f"{tight.url}/api/scenes", headers=origin)
    assert "access-control-allow-origin" not in response.headers
    foreign = walk_to(tight, origin="http://evil.example")
    assert "may not open walk-throughs" in foreign.next()["message"]
    own = walk_to(tight, origin=tight.url)  # the page the server itself serves
    own.send(type="hello", scene="sky", width=16, height=16)
    assert own.next()["type"] == "ready"
    with BackgroundServer(cors_origins=["http://friend.example"]) as server:
        preflight = httpx.options(
            f"{server.url}/api/render",
            headers={"origin": "http://friend.example", "access-control-request-method": "POST"},
        )
        assert preflight.headers["access-control-allow-origin"] == "http://friend.example"
        other = httpx.get(f"{server.url}/api/scenes", headers=origin)
        assert "access-control-allow-origin" not in other.headers
        friend = walk_to(server, origin="http://friend.example")
        friend.send(type="hello", scene="sky", width=16, height=16)
        assert friend.next()["type"] == "ready"


# ---- faults ----


def test_a_render_that_raises_answers_500_with_an_id_and_the_server_goes_on(tight, walk_to, caplog, monkeypatch):
    workshop = tight.app.state.service.workshop

    def broken(*args, **kwargs):
        raise RuntimeError("secret internals")

    walk = walk_to(tight)
    walk.send(type="hello", scene="sky", width=32, height=18)
    walk.next()
    walk.until_final()
    with caplog.at_level(logging.ERROR, logger="rcp.service"), monkeypatch.context() as patch:
        patch.setattr(workshop, "paint", broken)
        response = post(tight, {"scene": "sky", "width": 16, "height": 16})
        walk.send(type="camera", eye=[0, 0, 0], look_at=[0, 0.1, -1])
        session_error = walk.next()
    assert response.status_code == 500
    detail = response.json()["detail"]
    assert "secret" not in response.text and "Traceback" not in response.text
    error_id = detail.split()[2].rstrip(":")
    assert session_error["type"] == "error" and "internal error" in session_error["message"]
    logged = "\n".join(r.getMessage() + (r.exc_text or "") for r in caplog.records)
    assert f"error {error_id}" in logged and "secret internals" in caplog.text
    # both go on: the next render and the next camera are painted
    assert post(tight, {"scene": "sky", "width": 16, "height": 16}).status_code == 200
    walk.send(type="camera", eye=[0, 0, 0], look_at=[0, 0.2, -1], id=3)
    assert walk.frame()[0]["camera_id"] == 3


def test_broken_scenes_are_skipped_and_the_others_serve(tmp_path):
    camera = "[camera]\neye = [0, 0, 5]\nlook_at = [0, 0, 0]\n"
    (tmp_path / "plain.toml").write_text(camera + "[environment]\ncolor = [0.5, 0.6, 0.7]\n")
    (tmp_path / "typo.toml").write_text("[camera]\neye = [0, 0, 'up']\n")
    (tmp_path / "missing.toml").write_text(camera + "[[objects]]\nmesh = 'nowhere.obj'\n")
    (tmp_path / "garbage.ply").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "corrupt.toml").write_text(camera + "[[objects]]\nmesh = 'garbage.ply'\n")
    with BackgroundServer(scenes=tmp_path) as server:
        assert [s["name"] for s in httpx.get(f"{server.url}/api/scenes").json()] == ["plain"]
        assert post(server, {"scene": "corrupt"}).status_code == 404
        image = decode(post(server, {"scene": "plain", "width": 16, "height": 16}).content)
        assert image.shape == (16, 16, 3)


LONG = {"scene": "default", "width": 1920, "height": 1080, "paint": {"spp": 20}}  # far past the stop's grace
GRACE_S = 2  # the stop's grace (``RCP_STOP_GRACE_S``) in the first test: short, the render is longer


def test_a_stop_signal_ends_walks_and_renders_and_exits_cleanly_without_logging_the_token(tmp_path):
    auth = {"authorization": "Bearer hush-hush"}
    with rcp_serve(tmp_path, token="hush-hush", stop_grace_s=str(GRACE_S)) as served:
        walk = Walk(served, "?token=hush-hush")
        walk.send(type="hello", scene="default", width=640, height=360)
        walk.next()
        with ThreadPoolExecutor(1) as caller:
            render = caller.submit(lambda: post(served, LONG, headers=auth))
            wait_until(lambda: health(served, **auth)["renders"] == 1)  # the walk paints too
            clock = time.monotonic()
            served.process.send_signal(signal.SIGTERM)
            assert served.process.wait(WAIT_S) == 0
            assert time.monotonic() - clock >= GRACE_S  # the render had the grace to finish
            response = render.result(WAIT_S)
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                walk.ws.recv(10)
        assert closed.value.rcvd is None or closed.value.rcvd.code in (1001, 1012)
    # then it was told why it could not: a 503, not uvicorn's grace running out (a 500 and a traceback)
    assert response.status_code == 503 and response.json()["detail"] == "the server is stopping"
    assert response.headers["retry-after"]
    output = served.log.read_text()
    assert "stopping the paintings in progress" in output
    assert "token=***" in output and "hush-hush" not in output
    assert "Traceback" not in output and "cancelled" not in output.lower(), output


def test_a_second_ctrl_c_stops_the_paintings_at_once_and_still_answers(tmp_path):
    auth = {"authorization": "Bearer sesame"}
    # a grace of an hour: the render is stopped by the second Ctrl-C, or painted to its end (a 200)
    with rcp_serve(tmp_path, token="sesame", stop_grace_s="3600") as served, ThreadPoolExecutor(1) as caller:
        render = caller.submit(lambda: post(served, LONG, headers=auth))
        wait_until(lambda: health(served, **auth)["renders"] == 1)
        served.process.send_signal(signal.SIGINT)
        time.sleep(0.5)
        served.process.send_signal(signal.SIGINT)
        assert served.process.wait(WAIT_S) == 0
        response = render.result(WAIT_S)
    assert response.status_code == 503 and response.json()["detail"] == "the server is stopping"
    assert "Traceback" not in served.log.read_text()
