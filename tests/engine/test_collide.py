"""The walker's collisions (collide.py) in scenes built here: a floor, a wall, a railing and a flight of stairs."""

from __future__ import annotations

import numpy as np
import pytest

from rcp_server.engine.collide import STEP_OF_HEIGHT, Body, body_at, collide, floor_below
from rcp_server.engine.kernels.embree import Tracer

HEIGHT = 1.6  # the eye above the floor
RISE, RUN = 0.17, 0.3  # each stair: 17 cm up, 30 cm deep


def box(lo, hi) -> np.ndarray:
    """The 12 triangles of the box between corners ``lo`` and ``hi``: (12, 3, 3) float32."""
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], np.float32)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([[c[a], c[b], c[d]] for a, b, e, d in quads for b, d in ((b, e), (e, d))], np.float32)


def room(*boxes) -> Tracer:
    floor = box((-20, -1, -20), (20, 0, 20))
    return Tracer(np.concatenate([floor, *(box(lo, hi) for lo, hi in boxes)]))


def walk(tracer, eye, step, count, body) -> np.ndarray:
    eye = np.asarray(eye, np.float64)
    for _ in range(count):
        eye = collide(tracer, eye, step, body)
    return eye


def test_the_body_measures_its_height_and_scales_its_radius_to_it():
    tracer = room()
    body = body_at(tracer, (0, HEIGHT, 0), diagonal=60.0)
    assert body.height == pytest.approx(HEIGHT, abs=1e-5)
    assert body.radius == pytest.approx(0.15 * HEIGHT) and body.step == pytest.approx(STEP_OF_HEIGHT * HEIGHT)
    # the scene's size bounds the radius: a tiny body in a huge scene, a giant in a small one
    assert body_at(tracer, (0, HEIGHT, 0), diagonal=1e3).radius == pytest.approx(0.15 * HEIGHT)
    assert body_at(tracer, (0, HEIGHT, 0), diagonal=1e5).radius == pytest.approx(10.0)
    assert body_at(tracer, (0, HEIGHT, 0), diagonal=1.0).radius == pytest.approx(0.02)
    flying = body_at(tracer, (0, -5, 0), diagonal=60.0)  # below the floor slab: nothing beneath
    assert flying.height is None and flying.radius == pytest.approx(0.12)


def test_open_ground_lets_a_move_through_exactly():
    tracer = room()
    body = body_at(tracer, (0, HEIGHT, 0), 60.0)
    end = collide(tracer, (0, HEIGHT, 0), (0.3, 0, -0.4), body)
    assert np.allclose(end, (0.3, HEIGHT, -0.4), atol=1e-5)
    assert collide(None, (1, 2, 3), (1, 1, 1), body).tolist() == [2, 3, 4]  # no surfaces: nothing stops it


def test_a_wall_stops_the_walker_at_its_radius_and_it_slides_along():
    tracer = room(((-10, 0, -3.2), (10, 4, -3.0)))  # a wall whose face is at z = -3
    body = body_at(tracer, (0, HEIGHT, 0), 60.0)
    end = walk(tracer, (0, HEIGHT, 0), (0, 0, -0.1), 60, body)  # 6 units straight at it
    assert end[2] == pytest.approx(-3 + body.radius, abs=1e-3)
    assert end[0] == pytest.approx(0) and end[1] == pytest.approx(HEIGHT, abs=1e-5)
    # at an angle, it keeps the distance and slides along the wall
    slid = walk(tracer, end, (0.1, 0, -0.1), 20, body)
    assert slid[2] == pytest.approx(-3 + body.radius, abs=1e-3) and slid[0] == pytest.approx(2.0, abs=1e-3)
    # one long step (faster than any frame) does not pass through either
    assert collide(tracer, (0, HEIGHT, 0), (0, 0, -10), body)[2] == pytest.approx(-3 + body.radius, abs=1e-3)


def test_a_corner_holds_the_walker_in_both_directions():
    tracer = room(((-10, 0, -3.2), (10, 4, -3.0)), ((2.0, 0, -10), (2.2, 4, 10)))
    body = body_at(tracer, (0, HEIGHT, 0), 60.0)
    end = walk(tracer, (0, HEIGHT, 0), (0.1, 0, -0.1), 60, body)
    assert end[0] == pytest.approx(2 - body.radius, abs=1e-3) and end[2] == pytest.approx(-3 + body.radius, abs=1e-3)


def test_a_railing_at_hip_height_stops_the_walker_and_a_low_sill_is_stepped_over():
    railing = ((-10, 0.9, -2.05), (10, 1.0, -1.95))  # a 10 cm bar, hip high, with nothing under it
    post = ((-0.05, 0, -2.05), (0.05, 0.9, -1.95))
    tracer = room(railing, post)
    body = body_at(tracer, (1, HEIGHT, 0), 60.0)
    end = walk(tracer, (1, HEIGHT, 0), (0, 0, -0.1), 40, body)
    assert -2 < end[2] < -1.5 and end[1] == pytest.approx(HEIGHT, abs=1e-5)
    sill = room(((-10, 0, -2.05), (10, 0.1, -1.95)))
    over = walk(sill, (1, HEIGHT, 0), (0, 0, -0.1), 40, body_at(sill, (1, HEIGHT, 0), 60.0))
    assert over[2] == pytest.approx(-4.0, abs=1e-4) and over[1] == pytest.approx(HEIGHT, abs=1e-4)


def stairs(count: int, start_z: float = -2.0) -> list[tuple]:
    """A flight climbing towards -z: stair k from z = start - k RUN, its top at (k + 1) RISE."""
    return [((-1, 0, start_z - (k + 1) * RUN), (1, (k + 1) * RISE, start_z - k * RUN)) for k in range(count)]


def test_stairs_are_climbed_and_the_eye_keeps_its_height_above_each_tread():
    flight = stairs(12)
    tracer = room(*flight, ((-1, 0, -20), (1, 12 * RISE, -2 - 12 * RUN)))  # a landing at the top
    body = body_at(tracer, (0, HEIGHT, 0), 60.0)
    heights = []
    eye = np.array([0.0, HEIGHT, 0.0])
    for _ in range(80):
        eye = collide(tracer, eye, (0, 0, -0.1), body)
        heights.append(eye[1] - HEIGHT)
    assert eye[2] == pytest.approx(-8.0, abs=1e-3)  # it walked the whole way
    assert eye[1] == pytest.approx(HEIGHT + 12 * RISE, abs=1e-3)  # on the landing
    assert floor_below(tracer, eye) == pytest.approx(HEIGHT, abs=1e-3)
    assert np.all(np.diff(heights) >= -1e-6) and np.max(np.diff(heights)) <= RISE + 1e-4  # up, a stair at a time


def test_a_wall_higher_than_a_step_is_not_climbed():
    tracer = room(((-10, 0, -2.6), (10, 0.8, -2.0)))  # a block 80 cm high: more than a step
    body = body_at(tracer, (0, HEIGHT, 0), 60.0)
    assert body.step < 0.8
    end = walk(tracer, (0, HEIGHT, 0), (0, 0, -0.1), 40, body)
    assert end[1] == pytest.approx(HEIGHT, abs=1e-5) and end[2] > -2.0


def test_gravity_is_a_downward_move_that_the_floor_stops_and_a_ceiling_holds_the_radius():
    tracer = room(((-10, 2.5, -10), (10, 2.6, 10)))  # a ceiling at 2.5
    body = Body(radius=0.24, height=HEIGHT, step=0.45)
    fallen = walk(tracer, (0, 2.2, 0), (0, -0.1, 0), 20, body)
    assert fallen[1] == pytest.approx(HEIGHT, abs=1e-5)  # landed: the legs stand on the floor
    risen = walk(tracer, (0, HEIGHT, 0), (0, 0.1, 0), 20, body)
    assert risen[1] == pytest.approx(2.5 - 0.24, abs=1e-3)
    # a flyer (no floor) keeps the radius below it too
    flyer = Body(radius=0.24, height=None, step=0.0)
    assert walk(tracer, (0, 1.0, 0), (0, -0.1, 0), 20, flyer)[1] == pytest.approx(0.24, abs=1e-3)


def test_stairs_are_walked_down_and_a_walker_that_rose_stays_up():
    tracer = room(*stairs(6, start_z=-2.0))
    body = body_at(tracer, (0, HEIGHT, 0), 60.0)
    top = walk(tracer, (0, HEIGHT, 0), (0, 0, -0.1), 36, body)  # up onto the top stair (z -3.8 to -3.5)
    assert top[1] == pytest.approx(HEIGHT + 6 * RISE, abs=1e-3)
    down = walk(tracer, top, (0, 0, 0.1), 36, body)
    assert down[1] == pytest.approx(HEIGHT, abs=1e-3) and down[2] == pytest.approx(0.0, abs=1e-3)
    risen = collide(tracer, down, (0, 0.3, 0), body)
    assert walk(tracer, risen, (0.1, 0, 0), 5, body)[1] == pytest.approx(HEIGHT + 0.3, abs=1e-5)
