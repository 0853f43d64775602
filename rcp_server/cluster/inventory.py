"""The cluster's nodes and their cores, as Ray says, asked off the frames' path; and the autoscaler told what the
walkers need."""

from __future__ import annotations

import logging
import math
import threading
import time

from .connection import first_line, ray_module

log = logging.getLogger("rcp")

NODES_FRESH_S = 2.0  # the nodes and their cores are asked of Ray again after this long


class Inventory:
    """The live nodes' cores (node id -> CPUs): asked of Ray once, then again every ``NODES_FRESH_S`` on a thread
    (on a Ray that died, the question waits for a minute: no frame and no hello waits for it)."""

    def __init__(self) -> None:
        self._nodes: tuple[float, dict[str, float]] = (-math.inf, {})
        self._asker: threading.Thread | None = None
        self._asking: threading.Thread | None = None
        self.closed = False

    def cores(self) -> dict[str, float]:
        when, nodes = self._nodes
        if not nodes:
            self.ask()
        elif time.monotonic() - when > NODES_FRESH_S and not (self._asker and self._asker.is_alive()):
            self._asker = threading.Thread(target=self.ask, name="rcp-ray-nodes", daemon=True)
            self._asker.start()
        return self._nodes[1]

    def ask(self) -> None:
        """Ask Ray for its nodes now (waits for it)."""
        found = {n["NodeID"]: float(n["Resources"].get("CPU", 0.0)) for n in ray_module().nodes() if n["Alive"]}
        self._nodes = (time.monotonic(), {node: cpu for node, cpu in found.items() if cpu > 0})

    def forget(self) -> None:
        """Ray joined again: its nodes are asked afresh."""
        self._nodes = (-math.inf, {})

    def lost(self, node: str) -> None:
        """A node's worker was lost: it counts as gone until Ray says otherwise."""
        when, nodes = self._nodes
        self._nodes = (when, {n: c for n, c in nodes.items() if n != node})

    def autoscale(self, shares: list[float]) -> None:
        """Ask the autoscaler for the admitted walkers' cores (``shares``) and one more walker's: it adds a node
        before the next walker finds none, and lets one go when walkers leave (no autoscaler: nothing happens)."""
        if self.closed or not ray_module().is_initialized():  # Ray is down (a call could wait, or start one)
            return
        bundles = [{"CPU": s} for s in shares + shares[-1:]]
        self._asking = threading.Thread(target=_request, args=(bundles,), name="rcp-ray-autoscale", daemon=True)
        self._asking.start()

    def close(self) -> None:
        self.closed = True
        for thread in (self._asker, self._asking):  # no call of theirs may outlive Ray's shutdown
            if thread is not None:
                thread.join(1.0)


def _request(bundles: list[dict]) -> None:
    """Ask the autoscaler for ``bundles`` (on a thread: it waits for Ray's control store)."""
    try:
        from ray.autoscaler.sdk import request_resources

        request_resources(bundles=bundles)
    except Exception as exc:  # an old Ray, a client connection: the cluster keeps its size
        log.debug("walkers' resources not requested: %s", first_line(exc))
