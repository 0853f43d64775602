"""The workshop's fair pool: paintings take turns tile by tile, and a background lane takes only what the
foreground leaves."""

from __future__ import annotations

import threading

import pytest

from rcp_server.service.workshop import FairPool


def test_fair_pool_takes_paintings_in_turns():
    pool = FairPool(1)
    order: list[str] = []
    gate = threading.Event()
    pool.submit(gate.wait)  # hold the only worker while both batches queue
    first = pool.map(order.append, [f"a{k}" for k in range(3)])
    second = pool.map(order.append, [f"b{k}" for k in range(3)])
    gate.set()
    list(first), list(second)
    pool.shutdown()
    assert order == ["a0", "b0", "a1", "b1", "a2", "b2"]


def test_fair_pool_background_lane_takes_what_the_foreground_leaves():
    pool = FairPool(1)
    order: list[str] = []
    gate, painting, hold = threading.Event(), threading.Event(), threading.Event()

    def tile(name: str) -> None:
        order.append(name)
        if name == "v0":  # a video tile in progress keeps the worker while a walk frame comes
            painting.set()
            hold.wait(10)

    pool.submit(gate.wait, 10)
    video = pool.background.map(tile, [f"v{k}" for k in range(3)])  # queued before the walk's
    walk = pool.map(tile, ["w0", "w1"])
    gate.set()
    list(walk)
    assert painting.wait(10)
    later = pool.map(tile, ["w2"])
    hold.set()
    list(video), list(later)
    pool.shutdown()
    assert order == ["w0", "w1", "v0", "w2", "v1", "v2"]


def test_fair_pool_passes_errors_and_drops_the_rest_of_a_failed_batch():
    pool = FairPool(1)
    gate = threading.Event()
    pool.submit(gate.wait)
    ran = []
    failed = threading.Event()

    def work(k):
        ran.append(k)
        if k == 0:
            raise KeyError(k)
        failed.wait(10)  # tile 1 runs on while the caller sees the error and drops tiles 2 and 3

    results = pool.map(work, range(4))
    gate.set()
    with pytest.raises(KeyError):
        list(results)
    failed.set()
    pool.shutdown()
    assert ran == [0, 1]
