"""The one wait of the tests: ask again until something has happened, with a generous limit (two shared cores,
other work besides), so that a wait never bounds how fast anything happens. A test that means to bound a time
says so with a state (a message naming the limit, a count of what was done) or an injected clock instead."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

WAIT_S = 120.0  # how long a wait for something to happen may take before the test fails: generous on purpose

T = TypeVar("T")


def wait_until(ask: Callable[[], T], until: Callable[[T], object] = bool, timeout: float = WAIT_S, pause=0.02) -> T:
    """``ask()`` every ``pause`` s until ``until`` holds of its answer; that answer. Fails, showing the last answer,
    only after ``timeout`` s: a wait for a state, not a bound on the time it takes."""
    deadline = time.monotonic() + timeout
    while not until(answer := ask()):
        assert time.monotonic() < deadline, f"still {answer!r} after {timeout:g} s"
        time.sleep(pause)
    return answer
