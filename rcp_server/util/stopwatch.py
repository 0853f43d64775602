"""Thread time per stage of a tile's iterations: where a painting's time goes (``rcp bench speed`` prints it)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager

STAGES = ("camera", "intersect", "shade", "bookkeeping")
"""An iteration's stages, in order: camera assignment (mapping plus ray building), intersection (Embree),
shading (plus the per-pixel mean; the image method's lookup), bookkeeping (handing the new data on)."""


class Stopwatch:
    """Seconds spent in each of :data:`STAGES`, summed over every time that stage ran."""

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(STAGES, 0.0)

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the ``with`` block as part of stage ``name``."""
        clock = time.perf_counter()
        yield
        self.seconds[name] += time.perf_counter() - clock


def total(seconds: list[dict[str, float]]) -> dict[str, float]:
    """Stage seconds of several stopwatches (tiles, passes) summed per stage."""
    return {stage: sum(s[stage] for s in seconds) for stage in STAGES}
