"""The page trusts nothing it is given, in a real Chromium against a real server: names in its address that name
an object's prototype members, a bad quality, a token in the query, a walk to the edge of the space the server
paints (collide on and off), a film cancelled twice, and a walker refused with a time to come back."""

from __future__ import annotations

import json
import socket
import threading
import time
from urllib.parse import quote

import pytest
import uvicorn
from helpers.browser import SIZE, WAIT_MS, fresh_page, needs_chromium, sent, wait_final
from helpers.servers import BackgroundServer
from starlette.applications import Starlette
from starlette.routing import WebSocketRoute

from rcp_server.camera.camera import COORDINATE_LIMIT

pytestmark = needs_chromium

PROTOTYPE_NAMES = ("constructor", "toString", "valueOf", "hasOwnProperty", "__proto__", "isPrototypeOf")


def _url(server, query: str = "") -> str:
    return f"{server.url}/?scene=default&width={SIZE[0]}&height={SIZE[1]}{query}"


def test_a_link_with_prototype_names_keeps_its_good_settings_and_walks(browser, live_server):  # noqa: F811
    names = "".join(f"&{name}=1" for name in PROTOTYPE_NAMES)
    objects = quote(json.dumps({"__proto__": {"lambda_p": 1}}))
    url = _url(live_server, f"&style=focus&lambda_p=3{names}&materials={objects}")
    context, page, problems = fresh_page(browser, url)
    try:
        frame = wait_final(page)
        (notice,) = page.evaluate("rcp.state.errors")  # one notice, naming every name left out
        assert notice.startswith("This link's ")
        for name in PROTOTYPE_NAMES:
            assert f"'{name}' is no setting" in notice, name
        assert "materials '__proto__' names no object" in notice
        assert page.evaluate("JSON.stringify(rcp.state.paint)") == json.dumps(
            {"style": "focus", "lambda_p": 3}, separators=(",", ":")
        )
        assert frame["paint"]["lambda_p"] == 3  # the server took the link's good settings: nothing refused them
        assert page.evaluate("Object.prototype.polluted === undefined && ({}).lambda_p === undefined")
        assert not any(name in m for m in sent(page, "paint") for name in PROTOTYPE_NAMES)
    finally:
        context.close()
    assert problems == []


@pytest.mark.parametrize("quality", ["101", "7.5", "0", "x", ""])
def test_a_bad_quality_in_the_link_is_one_notice_and_the_page_walks(browser, live_server, quality):  # noqa: F811
    context, page, problems = fresh_page(browser, _url(live_server, f"&quality={quality}&lambda_p=2"))
    try:
        wait_final(page)
        (notice,) = page.evaluate("rcp.state.errors")
        assert notice.startswith("This link's quality ") and notice.endswith(": left out")
        (hello,) = sent(page, "hello")
        assert hello["quality"] == 80  # the page's own
        assert page.evaluate("rcp.state.paint") == {"lambda_p": 2}  # the rest of the link holds
        assert "quality" not in page.evaluate("rcp.shareLink()")
    finally:
        context.close()
    assert problems == []


@pytest.mark.parametrize("where", ["query", "fragment"])
def test_a_token_leaves_the_address_at_once_from_the_query_or_the_fragment(browser, where):  # noqa: F811
    with BackgroundServer(settle_ms=80, token="sesame") as server:
        given = "&token=sesame" if where == "query" else "#token=sesame"
        url = f"{server.url}/?scene=sky&width=64&height=48&lambda_p=2{given}"
        context, page, problems = fresh_page(browser, url)
        try:
            # the first thing the page does: no script after it, nor a frame, sees the token in the address
            assert "sesame" not in page.evaluate("location.href")
            wait_final(page)
            assert "sesame" not in page.evaluate("location.href")
            assert "sesame" not in page.evaluate("rcp.shareLink()")
            assert page.evaluate("sessionStorage.getItem('rcp.token')") == "sesame"  # this tab keeps it
            assert page.evaluate("rcp.state.paint") == {"lambda_p": 2} and page.evaluate("rcp.state.errors") == []
        finally:
            context.close()
        assert problems == []


@pytest.mark.parametrize("collide", [True, False])
def test_a_walk_to_the_edge_of_the_painted_space_stops_there_with_one_notice(browser, live_server, collide):  # noqa: F811
    edge = COORDINATE_LIMIT - 50
    camera = f"&eye={edge:.0f},1.7,0&look_at={edge + 10:.0f},1.7,0&collide={int(collide)}"
    context, page, problems = fresh_page(browser, _url(live_server, camera))
    try:
        wait_final(page)
        page.evaluate("rcp.walk.speed = 400")  # scene units a second, towards +x: over the edge within a second
        page.keyboard.down("w")
        page.wait_for_function(f"rcp.walk.walk.eye[0] >= {COORDINATE_LIMIT - 20} && rcp.state.atBound", timeout=WAIT_MS)
        page.wait_for_timeout(1000)  # pressing on at the edge: the input
        page.keyboard.up("w")
        # the page still animates: a turn still turns the view
        yaw = page.evaluate("rcp.walk.walk.yaw")
        page.keyboard.down("ArrowLeft")
        page.wait_for_function(f"rcp.walk.walk.yaw < {yaw - 0.05}", timeout=WAIT_MS)
        page.keyboard.up("ArrowLeft")
        wait_final(page, current=True)
        (notice,) = page.evaluate("rcp.state.errors")
        assert "edge of the space painted here" in notice
        cameras = sent(page, "camera")
        assert cameras and all(abs(x) <= COORDINATE_LIMIT for c in cameras for x in c["eye"] + c["look_at"])
        assert all(abs(x) <= COORDINATE_LIMIT for m in sent(page, "move") for x in m["eye"])
        assert bool(sent(page, "move")) == collide
    finally:
        context.close()
    assert problems == []


def test_a_film_cancelled_twice_is_cancelled_once(browser, live_server):  # noqa: F811
    context, page, problems = fresh_page(browser, f"{live_server.url}/?scene=sky&width=64&height=48")
    try:
        page.wait_for_function("rcp.state.scene !== null && rcp.overlay.frame", timeout=WAIT_MS)
        add = page.locator("#path [data-path=add]")
        add.click()
        page.evaluate("rcp.walk.place({eye: [0, 1.6, 0], look_at: [3, 1.6, -3], up: [0, 1, 0], fov: 50})")
        add.click()
        page.fill("#path li[data-index='1'] input", "10")  # a long film: it cannot end before the cancels
        page.dispatch_event("#path li[data-index='1'] input", "change")
        page.select_option("#path-size", "1920x1080")
        with page.expect_request(lambda r: r.method == "POST" and r.url.endswith("/api/videos")):
            page.locator("#path [data-path=render]").click()
        page.wait_for_function("rcp.path.job !== null", timeout=WAIT_MS)
        deletes: list[str] = []
        page.on("request", lambda r: deletes.append(r.url) if r.method == "DELETE" else None)
        # two clicks in one task: the second comes before the first is answered, whatever the machine's load
        page.evaluate("() => { const b = document.querySelector('#path [data-path=cancel]'); b.click(); b.click(); }")
        page.wait_for_function("rcp.path.job === null", timeout=WAIT_MS)
        page.wait_for_timeout(1500)  # three polls' time: anything still running has finished
        assert page.text_content("#path [data-path=status]").startswith("cancelled")
        assert len(deletes) == 1
        assert page.is_enabled("#path [data-path=render]")
    finally:
        context.close()
    assert problems == []


# ---- a walker refused with a time to come back ----


class _Refuser:
    """A WebSocket peer on loopback that closes every socket at once with the code and reason it is asked for
    (``/ws?code=1013&reason=...``): what a server that refuses a walker at hello does."""

    def __init__(self):
        async def refuse(ws):
            await ws.accept()
            await ws.close(code=int(ws.query_params["code"]), reason=ws.query_params["reason"])

        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            self.port = probe.getsockname()[1]
        config = uvicorn.Config(Starlette(routes=[WebSocketRoute("/ws", refuse)]), port=self.port, log_level="error")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def url(self, code: int, reason: str) -> str:
        return f"ws://127.0.0.1:{self.port}/ws?code={code}&reason={quote(reason)}"

    def __enter__(self):
        self.thread.start()
        while not self.server.started:
            time.sleep(0.05)
        return self

    def __exit__(self, *exc):
        self.server.should_exit = True
        self.thread.join()


@pytest.mark.parametrize(
    ("code", "reason", "meaning"),
    [
        (1013, "no room on the cluster for another walker; try again in 1 s", "hold"),
        (1008, "no room on the cluster for another walker; try again in 1.5 s", "hold"),
        (4003, "refused for now: try again in 2 s", "hold"),
        (1008, "this server needs a token", "refused"),
        (4003, "refused", "refused"),
        (1013, "the server is starting: compiling kernels (3/14); try again in 1 s", "retry"),
        (1013, "the server is at its limit of 1 walk-throughs; try again later", "retry"),
        (1006, "", "retry"),
    ],
)
def test_a_close_is_held_for_its_stated_time_refused_or_retried(page_at_server, code, reason, meaning):
    got = page_at_server.evaluate(
        "async ([code, reason]) => (await import('./connection.js')).closeMeaning(code, reason)", [code, reason]
    )
    assert got == meaning


@pytest.fixture(scope="module")
def page_at_server(browser, live_server):  # noqa: F811
    context = browser.new_context()
    page = context.new_page()
    page.goto(f"{live_server.url}/?scene=sky&width=64&height=48")
    page.wait_for_function("rcp.state.scene !== null", timeout=WAIT_MS)
    yield page
    context.close()


def test_a_refused_walker_shows_the_line_then_offers_to_try_again(browser, live_server):  # noqa: F811
    reason = "no room on the cluster for another walker; try again in 1 s"
    with _Refuser() as refuser:
        context, page, problems = fresh_page(browser, f"{live_server.url}/?scene=sky&width=64&height=48")
        try:
            wait_final(page)
            page.evaluate(
                "(url) => { rcp.connection.url = url; rcp.connection.socket.close(); }", refuser.url(1013, reason)
            )
            page.wait_for_function("rcp.connection.state === 'held'", timeout=WAIT_MS)
            assert page.text_content("#o-connection") == f"{reason} · 1 s"
            assert page.is_hidden("#o-retry")
            held_at = time.monotonic()
            page.wait_for_function("rcp.connection.state === 'offered'", timeout=WAIT_MS)
            assert time.monotonic() - held_at >= 0.5  # not before its time (the state was read a little late)
            assert page.text_content("#o-connection") == reason and page.is_visible("#o-retry")
            opens, frames = page.evaluate("[rcp.connection.opens, rcp.overlay.frames]")
            page.evaluate("(url) => { rcp.connection.url = url; }", live_server.ws_url)
            page.click("#o-retry")  # the server has room again
            page.wait_for_function(
                f"rcp.connection.opens > {opens} && rcp.connection.state === 'open'", timeout=WAIT_MS
            )
            assert page.is_hidden("#o-retry")
            page.wait_for_function(f"rcp.overlay.frames > {frames} && rcp.overlay.frame.final", timeout=WAIT_MS)
        finally:
            context.close()
        assert problems == []
