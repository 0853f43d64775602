"""The walkers' admission arithmetic, without Ray: shares from the measured cost, whole walkers per node, the
node with the most room, and a cost that one odd frame moves only so far."""

from __future__ import annotations

import pytest

from rcp_server.cluster.admission import CostMeter, Target, capacity, pick_node, share


def test_a_walker_takes_its_frames_cost_and_nodes_hold_whole_walkers():
    cost = CostMeter()
    cost.calibrated(frame_s=0.004, ray_s=1e-7)
    walker = share(Target(20, 100, 50), spp=1, iterations=6, cost=cost)  # 20 x (4 ms + 30,000 rays x 0.1 us)
    assert walker == pytest.approx(20 * (0.004 + 0.003))
    assert capacity({"a": 2.0, "b": 2.0}, walker) == 2 * 14  # 2 / 0.14 = 14.3 walkers a node, whole ones
    assert pick_node({"a": 2.0, "b": 2.0}, {"a": 0.5}, 0.6) == "b"
    assert pick_node({"a": 2.0, "b": 2.0}, {"a": 1.5, "b": 1.5}, 0.5) in ("a", "b")
    assert pick_node({"a": 2.0, "b": 2.0}, {"a": 1.5, "b": 1.6}, 0.5) == "a"
    assert pick_node({"a": 2.0}, {"a": 1.6}, 0.5) is None


def test_frames_move_the_cost_by_their_kind_and_an_outlier_only_so_far():
    cost = CostMeter(weight=0.5)
    cost.calibrated(frame_s=0.004, ray_s=1e-7)
    cost.measured(cpu_s=0.004 + 1e6 * 2e-7, rays=1_000_000)  # a large frame: its rays cost twice as much
    assert cost.ray_s == pytest.approx(1.5e-7) and cost.frame_s == 0.004
    cost.measured(cpu_s=0.006 + 100 * 1.5e-7, rays=100)  # a tiny frame says what the fixed part costs
    assert cost.frame_s == pytest.approx(0.005) and cost.ray_s == pytest.approx(1.5e-7)
    cost.measured(cpu_s=1.0, rays=100)  # a process's first frame: counted as at most 3 times the mean
    assert cost.frame_s == pytest.approx(0.5 * 0.005 + 0.5 * 3 * 0.005)
