"""``rcp serve`` as a user starts it: its port from the environment, a clean stop, a bad port refused."""

from __future__ import annotations

import time

import httpx
import pytest


def test_rcp_serve_takes_its_port_from_the_environment_and_stops_cleanly():
    import os
    import signal
    import subprocess
    import sys

    from rcp_server.bench.harness import free_port

    port = free_port()
    env = {**os.environ, "RCP_PORT": str(port)}
    server = subprocess.Popen([sys.executable, "-m", "rcp_server.cli", "serve"], env=env, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while True:
            try:
                health = httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1)
                break
            except httpx.TransportError:
                assert server.poll() is None and time.monotonic() < deadline, "rcp serve did not come up"
                time.sleep(0.2)
        assert health.json()["status"] == "ok"
        assert "<canvas" in httpx.get(f"http://127.0.0.1:{port}/").text  # the client, at /
    finally:
        server.send_signal(signal.SIGINT)
        assert server.wait(30) == 0
    assert b"serving 4 scenes" in server.stderr.read()


@pytest.mark.parametrize("argv", [["serve", "--port", "70000"], ["serve", "--port", "http"]])
def test_rcp_serve_refuses_a_bad_port_in_one_line(argv, capsys):
    from rcp_server.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("rcp: error:") and err.count("\n") == 1 and "port" in err
