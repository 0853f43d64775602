"""Idle and slow connections cannot starve the service (``service/guard.py``), tried as an attacker would,
against a real server on loopback, with bounded counts: half-open requests, WebSockets that never say hello,
requests that fill the capacity, a client that never reads its answer. Each deadline is checked by what the
server says or does when it passes (a 408, an error message, a closed socket) and by its lower bound: nothing
is cut before its time."""

from __future__ import annotations

import contextlib
import json
import socket
import time

import httpx
import pytest
from helpers.servers import BackgroundServer
from helpers.waits import wait_until
from websockets.exceptions import ConnectionClosed

SMALL = {"scene": "sky", "width": 32, "height": 18}
BOUND_S = 30  # generous: what a real client may wait for an answer on two busy cores
HALF_A_BODY = b"POST /api/render HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
HALF_A_BODY += b"Content-Length: 200\r\n\r\n{"  # 1 of its 200 bytes


@contextlib.contextmanager
def half_requests(port: int, count: int, head: bytes = b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: "):
    """``count`` connections that each send ``head`` (half a request) and then wait."""
    with contextlib.ExitStack() as stack:
        socks = []
        for _ in range(count):
            sock = stack.enter_context(socket.create_connection(("127.0.0.1", port), timeout=BOUND_S))
            sock.sendall(head)
            socks.append(sock)
        yield socks


def read_to_end(sock: socket.socket, seconds: float) -> bytes:
    """What the server sends until it closes the connection (fails if it has not within ``seconds``)."""
    sock.settimeout(seconds)
    data = b""
    while chunk := sock.recv(65536):
        data += chunk
    return data


def connections(server) -> int:
    """Connections the server holds open (uvicorn's own count, HTTP and WebSocket)."""
    return len(server.server.server_state.connections)


def test_half_open_requests_neither_starve_health_and_renders_nor_stay_open():
    timeout = 2.0
    with BackgroundServer(header_timeout_s=timeout, max_connections=64) as server:
        with half_requests(server.settings.port, 200) as socks:
            with httpx.Client(timeout=BOUND_S) as http:  # a real client, on its own connection
                health = http.get(f"{server.url}/api/health")
                assert health.status_code == 200 and health.json()["status"] == "ok"
                render = http.post(f"{server.url}/api/render", json=SMALL)
                assert render.status_code == 200 and render.headers["content-type"] == "image/png"
            assert connections(server) <= 64  # the idle ones were closed to make room
            # every half-open connection is closed by the server: evicted at once, or at the deadline with a 408
            answers = [read_to_end(sock, timeout + BOUND_S) for sock in socks]
        timed_out = [a for a in answers if a]
        assert timed_out and len(timed_out) <= 64
        for answer in timed_out:
            head, _, body = answer.partition(b"\r\n\r\n")
            assert head.startswith(b"HTTP/1.1 408") and json.loads(body) == {"detail": "no whole request within 2 s"}
        wait_until(lambda: connections(server) == 0)  # every connection closed


def test_a_slow_body_is_cut_off_at_the_deadline():
    with BackgroundServer(header_timeout_s=1.0) as server:
        head = HALF_A_BODY
        with half_requests(server.settings.port, 1, head) as (sock,):
            clock = time.monotonic()
            assert read_to_end(sock, BOUND_S) == b""  # the app saw a disconnect: no answer, the socket closed
            assert time.monotonic() - clock > 0.9  # at its deadline, not before


def test_requests_past_the_capacity_get_a_json_503_with_retry_after_until_the_stalled_ones_are_cut():
    head = HALF_A_BODY
    with BackgroundServer(max_requests=3, header_timeout_s=2.0) as server:
        with half_requests(server.settings.port, 3, head):  # three requests in progress, waiting on their bodies
            responses = []

            def refused() -> bool:
                responses.append(httpx.post(f"{server.url}/api/render", json=SMALL, timeout=BOUND_S))
                return responses[-1].status_code == 503

            wait_until(refused)
            busy = responses[-1]
            assert busy.headers["content-type"] == "application/json" and int(busy.headers["retry-after"]) >= 1
            assert busy.json() == {"detail": "the server has 3 requests in progress, its limit; try again shortly"}
            # the stalled requests are cut at their deadline, and the capacity is free again
            wait_until(lambda: httpx.post(f"{server.url}/api/render", json=SMALL, timeout=BOUND_S).status_code == 200)


def test_a_websocket_that_never_says_hello_is_closed_and_holds_no_place(walk_to):
    with BackgroundServer(hello_timeout_s=1.0, max_sessions=1, settle_ms=50) as server:
        silent = walk_to(server)
        clock = time.monotonic()
        walker = walk_to(server)  # the only walk-through place: the silent socket does not hold it
        walker.send(type="hello", scene="sky", width=32, height=18)
        assert walker.next()["type"] == "ready"
        assert silent.next(BOUND_S) == {"type": "error", "message": "no hello within 1 s", "answers": None, "id": None}
        with pytest.raises(ConnectionClosed) as closed:
            silent.next(BOUND_S)
        assert closed.value.rcvd.code == 1008 and time.monotonic() - clock > 0.9  # at its deadline, not before
        walker.send(type="camera", eye=[0, 1, 5], look_at=[0, 1, 0])  # the walker is still served
        walker.frame()


def test_a_client_that_never_reads_its_answer_is_let_go():
    # a PNG of some 2 MB: far more than the kernel buffers and the transport hold for a client that reads nothing
    body = json.dumps({"scene": "default", "width": 4096, "height": 2048, "paint": {"iterations": 1}}).encode()
    request = b"POST /api/render HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
    request += b"Content-Length: %d\r\n\r\n%s" % (len(body), body)
    with BackgroundServer(send_timeout_s=1.0) as server:
        with socket.socket() as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.connect(("127.0.0.1", server.settings.port))
            sock.sendall(request)
            wait_until(lambda: connections(server) == 0)  # the server let the client go (painting included)
            assert httpx.get(f"{server.url}/api/health", timeout=BOUND_S).status_code == 200


def test_the_walk_through_places_go_to_those_that_say_hello_first(walk_to):
    with BackgroundServer(max_sessions=1, settle_ms=50) as server:
        first, second = walk_to(server), walk_to(server)  # both let in: neither holds a place yet
        first.send(type="hello", scene="sky", width=32, height=18)
        assert first.next()["type"] == "ready"
        second.send(type="hello", scene="sky", width=32, height=18)
        assert second.next() == {
            "type": "error",
            "message": "the server is at its limit of 1 walk-throughs; try again in 30 s",
            "answers": "hello",
            "id": None,
        }
