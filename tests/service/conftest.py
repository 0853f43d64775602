"""The service's fixtures: a real server on loopback, and walks on it (``helpers/wire.py``)."""

from __future__ import annotations

import pytest
from helpers.wire import Walk


@pytest.fixture
def walk_to():
    """Opens walk-throughs (``walk_to(server)``); all are closed after the test."""
    opened: list[Walk] = []

    def open_walk(server, path: str = "", **options) -> Walk:
        opened.append(Walk(server, path, **options))
        return opened[-1]

    yield open_walk
    for client in opened:
        client.close()


@pytest.fixture
def walk(live_server, walk_to):
    return walk_to(live_server)
