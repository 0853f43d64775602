"""How many walkers a cluster holds, and where the next one goes: arithmetic on measured figures, no Ray.

A walker is admitted for a declared target (``fps`` frames a second of ``width x height`` pixels at its
painting's samples and iterations). What one frame costs is measured, not assumed (:class:`CostMeter`): the CPU
seconds a worker spends on any frame (the call, encoding, Ray's own threads) and on each ray (a pixel's sample
through one iteration), measured on a worker at start-up and kept up to date by every frame painted. A
walker then needs ``share`` cores, and a node of ``c`` cores holds ``c // share`` walkers; a walker goes to
the node with the most cores left (:func:`pick_node`), or is told in one line that there is no room and when to
try again (:class:`Full`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

OUTLIER = 3.0  # one frame moves the cost as if it cost at most this many times the mean (a process's first)
SHARE_LEAST = 0.01  # cores: the smallest share a walker is counted for (a tiny target still costs something)


@dataclass(frozen=True)
class Target:
    """What each walker is admitted for: ``fps`` frames a second of ``width x height`` pixels."""

    fps: float
    width: int
    height: int

    def __str__(self) -> str:
        return f"{self.fps:g} fps at {self.width}x{self.height}"


@dataclass
class CostMeter:
    """What a frame of ``rays`` rays costs a worker: ``frame_s + rays * ray_s`` CPU seconds. Measured once
        (:meth:`calibrated`), then moved by each frame (:meth:`measured`) by ``weight``: a frame whose rays cost
        more than its fixed part moves ``ray_s``, a smaller one ``frame_s`` (tiny frames say nothing about rays), each
    as if it cost at most ``OUTLIER`` times the mean."""

    frame_s: float | None = None
    ray_s: float | None = None
    weight: float = 0.2

    def calibrated(self, frame_s: float, ray_s: float) -> None:
        self.frame_s, self.ray_s = max(0.0, frame_s), max(ray_s, 1e-12)

    def measured(self, cpu_s: float, rays: int) -> None:
        if self.frame_s is None or self.ray_s is None or rays <= 0:
            return
        w, most = self.weight, OUTLIER
        if rays * self.ray_s >= self.frame_s:
            value = max(cpu_s - self.frame_s, 0.0) / rays
            self.ray_s = (1 - w) * self.ray_s + w * min(value, most * self.ray_s)
        else:
            value = max(cpu_s - rays * self.ray_s, 0.0)
            self.frame_s = (1 - w) * self.frame_s + w * min(value, most * self.frame_s)

    def frame_cpu_s(self, rays: int) -> float:
        """CPU seconds a frame of ``rays`` rays costs."""
        assert self.frame_s is not None and self.ray_s is not None, "measured first"
        return self.frame_s + rays * self.ray_s


def share(target: Target, spp: int, iterations: int, cost: CostMeter) -> float:
    """Cores one walker takes at ``target``, its frames of ``spp`` samples and ``iterations`` iterations."""
    return max(SHARE_LEAST, target.fps * cost.frame_cpu_s(target.width * target.height * spp * iterations))


def capacity(cores: dict[str, float], walker: float) -> int:
    """Walkers of ``walker`` cores each that nodes of ``cores`` (node -> cores) hold: whole walkers per node."""
    return sum(math.floor(c / walker + 1e-9) for c in cores.values())


def pick_node(cores: dict[str, float], taken: dict[str, float], walker: float) -> str | None:
    """The node with the most cores left (``cores`` less ``taken``, node -> cores) that holds a walker of
    ``walker`` cores; None when none does."""
    left = {node: c - taken.get(node, 0.0) for node, c in cores.items()}
    fits = [node for node, free in left.items() if free + 1e-9 >= walker]
    return max(fits, key=lambda node: (left[node], node)) if fits else None


class Full(Exception):
    """No node has room for one more walker; one line that says why, and ``retry_after`` seconds."""

    def __init__(self, reason: str, retry_after: int):
        super().__init__(f"{reason}; try again in {retry_after} s")
        self.reason = reason
        self.retry_after = retry_after


# ---- a walker's crew: its frame in bands over several nodes ----

BAND_ROWS_LEAST = 8  # a band of fewer rows is not worth a call of its own


def crew_size(nodes: int, rows: int, paint_s: float | None, overhead_s: float | None) -> int:
    """How many of ``nodes`` help paint one walker's frame of ``rows`` rows, in bands: each band at least
    ``BAND_ROWS_LEAST`` rows, and (once measured) each node's share of the frame's painting, ``paint_s`` wall seconds
    on one node, at least the ``overhead_s`` a call costs beyond its painting: past that a node adds more overhead
    than painting (its efficiency under one half)."""
    most = max(1, min(nodes, rows // BAND_ROWS_LEAST))
    if paint_s is None or overhead_s is None or overhead_s <= 0:
        return most
    return max(1, min(most, math.floor(paint_s / overhead_s)))


def crews(nodes: list[str], walkers: list[tuple[object, str]]) -> dict[object, list[str]]:
    """Which nodes paint each walker's frames (``walkers``: each walker with its home node, in the order they came):
    alone, a walker gets every node; with others, the nodes are dealt out in turn, so each gets as many as the
    next (one more for the first few); past a node each, every walker paints on its home node alone."""
    ordered = sorted(nodes)
    if not walkers or not ordered:
        return {key: [home] for key, home in walkers}
    if len(walkers) > len(ordered):
        return {key: [home] for key, home in walkers}
    return {key: ordered[k :: len(walkers)] for k, (key, _) in enumerate(walkers)}


def band_rows(height: int, count: int) -> list[tuple[int, int]]:
    """``count`` bands of a ``height``-row frame as (first row, rows), top to bottom, as even as rows allow."""
    count = max(1, min(count, height))
    edges = [round(k * height / count) for k in range(count + 1)]
    return [(edges[k], edges[k + 1] - edges[k]) for k in range(count)]
