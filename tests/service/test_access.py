"""Who may call, against a real server on loopback: with a token, everything but ``/api/health`` needs it (the
API's own description included); only the names the server is served under reach it (DNS rebinding); a
foreign page cannot open a walk-through."""

from __future__ import annotations

import socket

import httpx
import pytest
from helpers.servers import BackgroundServer
from helpers.wire import Walk

from rcp_server.service.access import host_allowed
from rcp_server.service.settings import Settings

TOKEN = "open sesame"
DOCS = ["/openapi.json", "/docs", "/redoc", "/docs/oauth2-redirect"]


@pytest.fixture(scope="module")
def guarded(tmp_path_factory):
    with BackgroundServer(token=TOKEN, scenes=tmp_path_factory.mktemp("no-scenes")) as server:
        yield server


@pytest.mark.parametrize("method", ["GET", "HEAD"])
@pytest.mark.parametrize("path", DOCS)
def test_with_a_token_the_api_description_needs_it_too(guarded, path, method):
    """They answered 200 to anyone; now a 401 like every other route but /api/health."""
    without = httpx.request(method, guarded.url + path, timeout=30)
    assert without.status_code == 401 and without.headers["www-authenticate"] == "Bearer"
    for bearer in ({"headers": {"authorization": f"Bearer {TOKEN}"}}, {"params": {"token": TOKEN}}):
        assert httpx.request(method, guarded.url + path, timeout=30, **bearer).status_code == 200
    assert httpx.head(f"{guarded.url}/api/health", timeout=30).status_code in (200, 405)  # open to all


def test_a_page_opened_with_the_token_fetches_the_schema_with_it(guarded):
    page = httpx.get(f"{guarded.url}/docs", params={"token": TOKEN}, timeout=30).text
    assert "/openapi.json?token=open%20sesame" in page
    schema = httpx.get(f"{guarded.url}/openapi.json", params={"token": TOKEN}, timeout=30).json()
    assert "401" in schema["paths"]["/api/render"]["post"]["responses"]  # declared once, where routers are included
    assert "401" not in schema["paths"]["/api/health"]["get"]["responses"]


def test_a_rebound_name_reaches_nothing(live_server):
    """A page on evil.example whose name the attacker points at 127.0.0.1 (DNS rebinding) sends Host and Origin
    evil.example: no REST route, client file or walk-through answers it; the loopback names all do."""
    evil = {"host": "evil.example", "origin": "http://evil.example"}
    for method, path in (("GET", "/api/scenes"), ("POST", "/api/render"), ("GET", "/"), ("GET", "/api/health")):
        answer = httpx.request(method, live_server.url + path, headers=evil, json={"scene": "sky"}, timeout=30)
        assert answer.status_code == 403 and "does not answer to the name 'evil.example'" in answer.json()["detail"]
    assert handshake(live_server, "evil.example").startswith(b"HTTP/1.1 403 ")  # no walk-through opens
    assert handshake(live_server, "127.0.0.1").startswith(b"HTTP/1.1 101 ")
    for host in ("localhost", f"localhost:{live_server.settings.port}", "127.0.0.1", "[::1]:8000", "127.0.0.2"):
        assert httpx.get(f"{live_server.url}/api/health", headers={"host": host}, timeout=30).status_code == 200


def handshake(server, host: str) -> bytes:
    """The status line and headers a WebSocket handshake to ``/ws`` with this ``Host`` gets (the WebSocket
    client sets the Host from its address, so the request is written by hand)."""
    request = (
        f"GET /ws HTTP/1.1\r\nHost: {host}\r\nOrigin: http://{host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    with socket.create_connection(("127.0.0.1", server.settings.port), timeout=10) as sock:
        sock.sendall(request.encode())
        return sock.recv(4096)


def test_the_names_a_server_answers_to():
    loopback, public = Settings(host="127.0.0.1"), Settings(host="0.0.0.0")
    named = Settings(host="0.0.0.0", allowed_hosts="paint.example.org, Other.example")
    assert not host_allowed(loopback, "evil.example") and not host_allowed(loopback, "10.0.0.1:8000")
    assert host_allowed(loopback, "LOCALHOST:8000") and host_allowed(loopback, "::1")
    assert host_allowed(public, "evil.example")  # bound to every address: any name, unless told which
    assert host_allowed(named, "paint.example.org:443") and host_allowed(named, "other.example")
    assert not host_allowed(named, "evil.example") and host_allowed(named, "localhost")
    assert host_allowed(Settings(allowed_hosts="*"), "anything.example")


def test_a_foreign_origin_cannot_walk_even_under_a_served_name(live_server):
    foreign = Walk(live_server, origin="http://evil.example")
    assert "may not open walk-throughs" in foreign.next()["message"]
    foreign.close()
