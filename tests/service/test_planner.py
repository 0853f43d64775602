"""The walk/refine policy on a fake clock: ``now`` is a number the test picks, paintings are told, not made."""

from __future__ import annotations

from dataclasses import replace

import pytest

from rcp_server.service.planner import FIRST_SCALE, REFINE_SPP, SOON, Plan, Planner, View
from rcp_server.settings.params import PaintParams

PARAMS = PaintParams(iterations=6, spp=1)
WIDTH, HEIGHT = 160, 90
START = 100.0  # the fake clock when the walk-through opens, seconds
SETTLE_S = 0.15
BUDGET_S = 0.8 * 0.060  # the share of a 60 ms frame a walk frame's painting may take


def view(**changes) -> View:
    return View(**{"width": WIDTH, "height": HEIGHT, "params": PARAMS, "temporal": True, "moving": False, **changes})


def hello(now: float = START, **limits) -> Planner:
    """A planner as a session leaves it after its first hello at ``now``."""
    planner = Planner(**{"frame_ms": 60.0, "settle_ms": 150.0, "max_work": 1 << 28, "started": START, **limits})
    planner.scene_started(now)
    planner.view_changed()
    return planner


def move(planner: Planner, now: float) -> None:
    planner.camera_moved(now)
    planner.view_changed()


def first_walk_frame(planner: Planner, seconds_per_ray: float) -> Plan:
    """Paint the first walk frame as if one ray-iteration took ``seconds_per_ray``."""
    plan = planner.next_frame(START, view())
    planner.frame_painted(plan, seconds_per_ray * plan.width * plan.height * plan.params.iterations)
    return plan


# ---- walking ----


def test_the_first_frame_is_a_walk_frame_at_the_first_scale_from_the_canvas():
    planner = hello()
    width, height = round(WIDTH * FIRST_SCALE), round(HEIGHT * FIRST_SCALE)
    walk = PARAMS.at_scale(height / HEIGHT)  # lambda_p counts pixels: as long in the picture as on the canvas
    assert walk.lambda_p == pytest.approx(PARAMS.lambda_p * FIRST_SCALE, rel=0.02)
    assert planner.next_frame(START, view()) == Plan("walk", width, height, walk, False, 6, False, 0.0, 1)
    assert planner.until_rest(START, view()) is None  # a frame is due, not a rest


def test_temporal_walk_frames_continue_the_last_frame_one_iteration_and_sample_each():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    iterations = []
    for k in range(1, 4):
        move(planner, START + 0.05 * k)
        plan = planner.next_frame(START + 0.05 * k, view())
        walk = replace(PARAMS, iterations=1).at_scale(plan.height / HEIGHT)
        assert (plan.phase, plan.continues, plan.params) == ("walk", True, walk)
        iterations.append(plan.iteration)
        planner.frame_painted(plan, 0.01)
    assert iterations == [7, 8, 9]


def test_without_temporal_mode_every_walk_frame_paints_all_iterations_from_the_canvas():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    move(planner, START + 0.05)
    plan = planner.next_frame(START + 0.05, view(temporal=False))
    walk = PARAMS.at_scale(plan.height / HEIGHT)
    assert (plan.phase, plan.continues, plan.params, plan.iteration) == ("walk", False, walk, 6)


@pytest.mark.parametrize(
    ("affordable", "scale"),
    [(4.0, 1.0), (1.001, 1.0), (0.999, 0.875), (0.5626, 0.75), (0.5624, 0.625), (0.0626, 0.25), (0.01, 0.25)],
)
@pytest.mark.parametrize("temporal", [True, False])
def test_the_walk_scale_is_the_largest_that_holds_the_frame_budget(affordable, scale, temporal):
    """``affordable``: the share of the canvas's pixels a walk frame can paint within the budget."""
    iterations = 1 if temporal else PARAMS.iterations
    planner = hello()
    first_walk_frame(planner, BUDGET_S / (affordable * WIDTH * HEIGHT * iterations))
    move(planner, START + 0.05)
    plan = planner.next_frame(START + 0.05, view(temporal=temporal))
    assert (plan.width, plan.height) == (round(WIDTH * scale), round(HEIGHT * scale))


def test_the_measured_speed_is_a_running_mean_of_the_frames():
    planner = hello()
    plan = first_walk_frame(planner, 2e-6)
    move(planner, START + 0.05)
    planner.frame_painted(plan, 5e-6 * plan.width * plan.height * plan.params.iterations)
    assert planner.seconds_per_ray == pytest.approx(0.7 * 2e-6 + 0.3 * 5e-6, rel=1e-12)


# ---- resting and refining ----


def test_refinement_starts_once_the_camera_has_rested_for_settle_ms():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    moved = START + 1.0
    move(planner, moved)
    planner.frame_painted(planner.next_frame(moved, view()), 0.01)
    assert planner.next_frame(moved + 0.05, view()) is None
    assert planner.until_rest(moved + 0.05, view()) == pytest.approx(SETTLE_S - 0.05)
    assert planner.until_rest(moved + SETTLE_S - 0.001, view()) == SOON  # due: a short wait, never a spin
    plan = planner.next_frame(moved + SETTLE_S, view())
    assert plan == Plan("refine", WIDTH, HEIGHT, PARAMS, False, 6, False, 0.0, planner.version)


def rested(planner: Planner, params: PaintParams = PARAMS, now: float = START + 10.0) -> list[Plan]:
    """Every frame the planner asks for at ``now`` (the camera at rest), each painted at once, until none."""
    plans = []
    while (plan := planner.next_frame(now, view(params=params))) is not None:
        plans.append(plan)
        planner.frame_painted(plan, 0.01)
    assert planner.until_rest(now, view(params=params)) is None  # nothing more until the view changes
    return plans


def test_at_rest_the_full_painting_comes_first_then_more_samples_the_final_frame():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    plans = rested(planner)
    assert [(p.phase, p.width, p.height, p.params, p.final) for p in plans] == [
        ("refine", WIDTH, HEIGHT, PARAMS, False),
        ("refine", WIDTH, HEIGHT, replace(PARAMS, spp=REFINE_SPP), True),
    ]
    assert all(not p.continues and p.iteration == PARAMS.iterations for p in plans)


@pytest.mark.parametrize(
    ("spp", "affordable", "steps"),
    [
        (1, 1000, [1, REFINE_SPP]),
        (3, 1000, [3, 6]),  # twice the painting's own, when that is more than REFINE_SPP
        (40, 1000, [40, 64]),  # never past 64
        (64, 1000, [64]),  # already there: one refinement, the final one
        (1, 3, [1, 3]),  # capped by the work one painting may take
        (2, 2, [2]),
    ],
)
def test_refinement_samples_are_capped_by_max_work(spp, affordable, steps):
    params = replace(PARAMS, spp=spp)
    planner = hello(max_work=WIDTH * HEIGHT * PARAMS.iterations * affordable)
    first_walk_frame(planner, 1e-6)
    plans = rested(planner, params)
    assert [p.params.spp for p in plans] == steps
    assert [p.final for p in plans] == [False] * (len(steps) - 1) + [True]


def test_a_new_camera_walks_again_and_restarts_the_refinements():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    rested(planner)
    move(planner, START + 20.0)
    walk = planner.next_frame(START + 20.0, view())
    assert (walk.phase, walk.continues, walk.iteration) == ("walk", True, PARAMS.iterations + 1)
    planner.frame_painted(walk, 0.01)
    assert [p.params.spp for p in rested(planner, now=START + 30.0)] == [1, REFINE_SPP]


def test_a_refinement_painted_for_an_older_view_does_not_count():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    refine = planner.next_frame(START + 10.0, view())
    planner.view_changed()  # e.g. a paint message while it was painted
    planner.frame_painted(refine, 0.01)
    assert (planner.refinements, planner.painted_version) == (0, refine.version)
    assert planner.next_frame(START + 10.0, view()).phase == "walk"


def test_a_view_that_cannot_be_painted_is_not_tried_again_until_it_changes():
    planner = hello()
    plan = planner.next_frame(START, view())
    planner.frame_failed(plan, view())
    assert planner.next_frame(START + 10.0, view()) is None
    assert planner.until_rest(START + 10.0, view()) is None
    planner.view_changed()
    assert planner.next_frame(START + 10.0, view()).phase == "walk"


# ---- scenes and time ----


def test_a_new_scene_starts_again_from_the_canvas():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    planner.scene_started(START + 5.0)
    planner.view_changed()
    plan = planner.next_frame(START + 5.0, view())
    assert (plan.phase, plan.continues, plan.iteration) == ("walk", False, PARAMS.iterations)
    assert planner.next_frame(START + 5.0 + SETTLE_S, view()).phase == "walk"  # unpainted: no rest yet


def test_an_animated_scene_never_rests_and_its_frames_run_on_the_walk_throughs_clock():
    planner = hello()
    first_walk_frame(planner, 1e-6)
    for now in (START + 10.0, START + 13.5):
        plan = planner.next_frame(now, view(moving=True))
        assert (plan.phase, plan.time) == ("walk", now - START)
        planner.frame_painted(plan, 0.01)
    still = planner.next_frame(START + 14.0, view())
    assert (still.phase, still.time) == ("refine", 0.0)  # a still scene rests, at time 0


def test_a_stereo_pair_counts_both_eyes_in_the_samples_and_the_timing():
    """Refinement samples are sized from the pixels of both eyes (the work limit holds for the pair), and walk
    frames from the measured time of both eyes' rays: at the same speed per ray a pair's frames are smaller."""
    mono, pair = view(temporal=False), view(temporal=False, eyes=2)
    limit = WIDTH * HEIGHT * PARAMS.iterations * 6  # one eye affords 6 samples, a pair 3
    planner = hello(max_work=limit)
    assert planner.refine_spp(mono) == [1, REFINE_SPP] and planner.refine_spp(pair) == [1, 3]
    for v in (mono, pair):
        assert max(planner.refine_spp(v)) * WIDTH * HEIGHT * v.eyes * PARAMS.iterations <= limit
    scales = []
    for v in (mono, pair):
        planner = hello()
        plan = planner.next_frame(START, v)
        assert plan.eyes == v.eyes
        per_ray = BUDGET_S / (0.6 * WIDTH * HEIGHT * PARAMS.iterations)  # one eye affords 0.6 of the canvas
        planner.frame_painted(plan, per_ray * plan.width * plan.height * plan.eyes * plan.params.iterations)
        scales.append(planner.walk_scale(v))
    assert scales == [0.75, 0.5]  # 0.75^2 <= 0.6 for one eye; a pair paints twice the pixels: 0.5^2 <= 0.3
