"""Walking, not flying, in a real Chromium against a real server: a room built here (a wall, a flight of stairs)
is uploaded and walked through; the wall stops the walker at its radius, the stairs are climbed, and with
*Collide* off the walker passes through, as before. The 360° view walks the same way."""

from __future__ import annotations

import httpx
import numpy as np
import pytest
import trimesh
from helpers.browser import SOFTWARE_WEBGL, WAIT_MS, chromium, needs_chromium

pytestmark = needs_chromium

HEIGHT = 1.6
RISE, RUN, STAIRS = 0.17, 0.3, 8


def box(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2))


def room() -> bytes:
    """A floor; a wall across lane x in [-4, 4] with its face at z = -3; stairs up towards -z in lane x in [6, 10]
    from z = -2, each RISE high and RUN deep, to a landing."""
    parts = [box((-12, -0.2, -12), (12, 0, 12)), box((-4, 0, -3.3), (4, 3, -3))]
    parts += [box((6, 0, -2 - (k + 1) * RUN), (10, (k + 1) * RISE, -2 - k * RUN)) for k in range(STAIRS)]
    parts.append(box((6, 0, -9), (10, STAIRS * RISE, -2 - STAIRS * RUN)))
    return trimesh.util.concatenate(parts).export(file_type="glb")


@pytest.fixture(scope="module")
def browser():
    with chromium(*SOFTWARE_WEBGL) as launched:  # WebGL: the 360° view draws
        yield launched


@pytest.fixture(scope="module")
def hall(live_server) -> str:
    response = httpx.post(f"{live_server.url}/api/scenes", files={"file": ("hall.glb", room())}, timeout=120)
    assert response.status_code == 201, response.text
    return response.json()["name"]


def open_at(browser, live_server, hall, eye, extra: str = ""):
    """A fresh page on the hall at ``eye`` looking towards -z (a link), walking fast; (context, page, errors)."""
    context = browser.new_context(viewport={"width": 800, "height": 500})
    page = context.new_page()
    problems: list[str] = []
    page.on("console", lambda m: problems.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(str(e)))
    look = (eye[0], eye[1], eye[2] - 5)
    page.goto(
        f"{live_server.url}/?scene={hall}&width=160&height=100&eye={','.join(map(str, eye))}"
        f"&look_at={','.join(map(str, look))}{extra}"
    )
    page.wait_for_function("rcp.state.scene && rcp.collider.body !== null || !rcp.collider.enabled", timeout=WAIT_MS)
    page.evaluate("rcp.walk.speed = 3")
    return context, page, problems


def hold_w(page, ms: int) -> list[float]:
    page.click("#view", position={"x": 400, "y": 250})
    page.keyboard.down("w")
    page.wait_for_timeout(ms)  # the key is held this long: that is the input
    page.keyboard.up("w")
    page.wait_for_function("rcp.walk.velocity.every((v) => v === 0)", timeout=WAIT_MS)
    settled = "rcp.collider.flight === null && rcp.collider.pending.every((x) => x === 0)"
    page.wait_for_function(settled, timeout=WAIT_MS)
    return page.evaluate("rcp.walk.walk.eye")


def test_a_wall_stops_the_walker_at_its_radius_and_collide_off_walks_through(browser, live_server, hall):
    context, page, problems = open_at(browser, live_server, hall, (0, HEIGHT, 0))
    try:
        body = page.evaluate("rcp.collider.body")
        assert body["height"] == pytest.approx(HEIGHT, abs=1e-4) and body["standing"]
        assert body["radius"] == pytest.approx(0.15 * HEIGHT, rel=1e-4)
        eye = hold_w(page, 1500)  # 4.5 units at 3 a second: through the wall if nothing stopped it
        assert eye[2] == pytest.approx(-3 + body["radius"], abs=2e-3)
        assert eye[0] == pytest.approx(0, abs=1e-6) and eye[1] == pytest.approx(HEIGHT, abs=1e-4)
        page.wait_for_function(f"rcp.state.lastCamera.eye[2] === {round(eye[2], 5)}", timeout=WAIT_MS)
        assert "walker" in page.text_content("#overlay") and page.is_visible("#o-body")
        # with Collide off, the walk flies as before: through the wall
        page.uncheck("#collide")
        assert hold_w(page, 600)[2] < -3.3
        assert "collide=0" in page.evaluate("rcp.shareLink()")
    finally:
        context.close()
    assert problems == []


def test_stairs_are_climbed_a_stair_at_a_time(browser, live_server, hall):
    context, page, problems = open_at(browser, live_server, hall, (8, HEIGHT, 0))
    try:
        page.evaluate("""() => { window.heights = [];
            setInterval(() => heights.push(rcp.walk.walk.eye[1]), 20); }""")
        eye = hold_w(page, 2200)  # 6.6 units: up the flight onto the landing
        assert eye[2] < -2 - STAIRS * RUN  # on the landing
        assert eye[1] == pytest.approx(HEIGHT + STAIRS * RISE, abs=1e-3)
        heights = np.array(page.evaluate("heights"))
        assert np.all(np.diff(heights) >= -1e-6) and np.max(np.diff(heights)) <= RISE * 3 + 1e-4  # up, no jumps
        assert len(np.unique(np.round(heights, 4))) >= 4  # stair by stair
        # E rises off the landing and stays up; with gravity on, the walker falls back onto it
        page.keyboard.down("e")
        page.wait_for_timeout(300)
        page.keyboard.up("e")
        page.wait_for_function("rcp.walk.velocity.every((v) => v === 0) && rcp.collider.flight === null")
        risen = page.evaluate("rcp.walk.walk.eye")[1]
        assert risen > eye[1] + 0.2 and page.evaluate("rcp.collider.body.standing") is False
        page.wait_for_timeout(300)
        assert page.evaluate("rcp.walk.walk.eye")[1] == risen
        page.check("#gravity")
        page.wait_for_function("rcp.collider.body.standing", timeout=WAIT_MS)
        assert page.evaluate("rcp.walk.walk.eye")[1] == pytest.approx(HEIGHT + STAIRS * RISE, abs=1e-3)
    finally:
        context.close()
    assert problems == []


def test_the_360_view_walks_into_the_same_wall(browser, live_server, hall):
    context, page, problems = open_at(browser, live_server, hall, (0, HEIGHT, 0), "&projection=equirect")
    try:
        page.wait_for_function("rcp.view360.active", timeout=WAIT_MS)
        radius = page.evaluate("rcp.collider.body.radius")
        eye = hold_w(page, 1500)
        assert eye[2] == pytest.approx(-3 + radius, abs=2e-3)
        page.wait_for_function(f"rcp.state.lastCamera.eye[2] === {round(eye[2], 5)}", timeout=WAIT_MS)
        assert page.evaluate("rcp.state.lastCamera.projection") == "equirect"
    finally:
        context.close()
    assert problems == []
