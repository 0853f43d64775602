"""The tests' one door to real servers: ``rcp serve`` on 127.0.0.1 and a free port, in a thread of the test process
(``BackgroundServer``) or as a subprocess (``rcp_serve``; ``rcp_environment`` for a test that starts ``rcp``
itself), and the standard-library client that asks them (``request``, ``get_json``). They are the benchmarks'
own, from ``rcp_server/service/loopback.py``; no test module imports that module but this one.

Also the one wait of the tests: ``wait_until`` asks again until something has happened, with a generous limit
(two shared cores), so that it never bounds how fast anything happens.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

from rcp_server.service.loopback import BackgroundServer, free_port, get_json, rcp_environment, rcp_serve, request

__all__ = [
    "FINISHED",
    "WAIT_S",
    "BackgroundServer",
    "free_port",
    "get_json",
    "job_status",
    "rcp_environment",
    "rcp_serve",
    "request",
    "wait_until",
]

WAIT_S = 120.0  # how long a wait for something to happen may take before the test fails: generous on purpose
FINISHED = ("done", "failed", "cancelled")  # the states a job (a film, a print) ends in

T = TypeVar("T")


def wait_until(ask: Callable[[], T], until: Callable[[T], object] = bool, timeout: float = WAIT_S, pause=0.02) -> T:
    """``ask()`` every ``pause`` s until ``until`` holds of its answer; that answer. Fails, showing the last answer,
    only after ``timeout`` s: a wait for a state, not a bound on the time it takes."""
    deadline = time.monotonic() + timeout
    while not until(answer := ask()):
        assert time.monotonic() < deadline, f"still {answer!r} after {timeout:g} s"
        time.sleep(pause)
    return answer


def job_status(client, path: str, until: Callable[[dict], object] | None = None, timeout: float = WAIT_S) -> dict:
    """A job's status (``path``: ``/api/videos/<id>``, ``/api/prints/<id>``, through an ``httpx.Client``) once
    ``until`` holds of it; by default, once it has finished."""
    return wait_until(lambda: client.get(path).json(), until or (lambda status: status["state"] in FINISHED), timeout)
