"""The tests' one door to real servers: ``rcp serve`` on 127.0.0.1 and a free port, in a thread of the test process
(``BackgroundServer``) or as a subprocess (``rcp_serve``; ``rcp_environment`` for a test that starts ``rcp``
itself), and the standard-library client that asks them (``request``, ``get_json``). They are the benchmarks'
own, from ``rcp_server/service/loopback.py``; no test module imports that module but this one.

Also ``job_status``: a film's or a print's status once it has finished, or reached the state a test waits for.
"""

from __future__ import annotations

from collections.abc import Callable

from helpers.waits import WAIT_S, wait_until
from rcp_server.service.loopback import BackgroundServer, free_port, get_json, rcp_environment, rcp_serve, request

__all__ = [
    "FINISHED",
    "BackgroundServer",
    "free_port",
    "get_json",
    "job_status",
    "rcp_environment",
    "rcp_serve",
    "request",
]

FINISHED = ("done", "failed", "cancelled")  # the states a job (a film, a print) ends in


def job_status(client, path: str, until: Callable[[dict], object] | None = None, timeout: float = WAIT_S) -> dict:
    """A job's status (``path``: ``/api/videos/<id>``, ``/api/prints/<id>``, through an ``httpx.Client``) once
    ``until`` holds of it; by default, once it has finished."""
    return wait_until(lambda: client.get(path).json(), until or (lambda status: status["state"] in FINISHED), timeout)
