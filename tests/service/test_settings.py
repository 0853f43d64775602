"""The ``RCP_*`` settings checked as ``rcp serve`` and ``rcp compile`` start, on the real command line: an empty
value means the default (never the working directory), an empty token is refused, paths are folders that exist,
a host is an address of this machine; a bad value is one line naming the setting, and exit status 2."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from helpers.servers import free_port, rcp_environment
from pydantic import SecretStr
from starlette.datastructures import Headers, QueryParams

from rcp_server.service.access import admits
from rcp_server.service.settings import ENGINE_VARIABLES, Settings, unknown_variable

READY_S = 600  # a first start compiles the kernels: minutes on a machine shared with other work


def environment(tmp_path: Path, **settings: str) -> dict[str, str]:
    """This process's environment without any ``RCP_*`` of its own, with ``settings`` (``RCP_*`` names), the
    user's data folder in ``tmp_path`` and this checkout's code."""
    env = {name: value for name, value in os.environ.items() if not name.startswith("RCP_")}
    code = {name: rcp_environment()[name] for name in ("PYTHONPATH", "PYTHONUNBUFFERED")}
    return {**env, **code, "XDG_DATA_HOME": str(tmp_path / "xdg"), **settings}


def rcp(tmp_path: Path, *argv: str, **settings: str) -> subprocess.CompletedProcess:
    """``rcp *argv`` in a subprocess run in ``tmp_path``, to its end."""
    command = [sys.executable, "-m", "rcp_server.cli", *argv]
    env = environment(tmp_path, **settings)
    return subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60, check=False)


def bad_values(tmp_path: Path) -> list[tuple[str, str, str]]:
    """(setting, value, what the line says) for values no setting takes."""
    a_file = tmp_path / "a-file"
    a_file.write_text("not a folder")
    return [
        ("RCP_TOKEN", "", "RCP_TOKEN: empty"),
        ("RCP_TOKEN", "   ", "RCP_TOKEN: empty"),
        ("RCP_TOKEN", " sesame", "RCP_TOKEN: white space"),
        ("RCP_SCENES", str(tmp_path / "missing"), "no such folder"),
        ("RCP_SCENES", str(a_file), "not a folder"),
        ("RCP_CLIENT", str(tmp_path / "missing"), "no such folder"),
        ("RCP_CLIENT", str(tmp_path), "no index.html"),
        ("RCP_DATA", str(a_file), "not a folder"),
        ("RCP_HOST", "999.1.1.1", "does not resolve"),
        ("RCP_HOST", "no-such-host.invalid", "does not resolve"),
        ("RCP_HOST", "192.0.2.1", "not an address of this machine"),  # TEST-NET-1: nobody's
        ("RCP_PORT", "http", "valid integer"),
        ("RCP_PORT", "70000", "65535"),
        ("RCP_THREADS", "0", "greater than or equal to 1"),
        ("RCP_FRAME_MS", "nan", "finite"),
        ("RCP_RENDER_TIMEOUT_S", "inf", "finite"),
        ("RCP_UPLOADS", "perhaps", "boolean"),
        ("RCP_MAX_PIXEL", "100", "is no setting of rcp: did you mean RCP_MAX_PIXELS?"),  # misspelt: not ignored
        ("RCP_TOKN", "sesame", "did you mean RCP_TOKEN?"),
    ]


@pytest.mark.parametrize("command", ["serve", "compile"])
def test_each_bad_setting_is_one_line_naming_it_and_exit_2(tmp_path, command):
    for name, value, says in bad_values(tmp_path):
        if command == "compile" and name not in ("RCP_SCENES", "RCP_TOKEN", "RCP_HOST", "RCP_PORT"):
            continue  # every setting is read by both; a few are enough for the second
        given_port = command == "serve" and name != "RCP_PORT"  # --port would stand for RCP_PORT
        run = rcp(tmp_path, command, *(["--port", str(free_port())] if given_port else []), **{name: value})
        line = f"{name}={value!r}: {run.stderr!r}"
        assert run.returncode == 2, line
        assert run.stderr.startswith(f"rcp: error: {name}") and run.stderr.count("\n") == 1, line
        assert says in run.stderr, line
        assert "Traceback" not in run.stderr and not run.stdout, line
        if name == "RCP_TOKEN":
            assert value.strip() == "" or value.strip() not in run.stderr  # never the token itself
    assert not (tmp_path / "xdg").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


def test_every_variable_something_reads_is_known_and_no_other():
    known = {f"RCP_{name.upper()}": "1" for name in Settings.model_fields} | dict.fromkeys(ENGINE_VARIABLES, "1")
    assert unknown_variable(known | {"PATH": "/bin", "RCPX": "1"}) is None
    assert unknown_variable(known | {"RCP_NOTHING_LIKE_IT": "1"}) == (
        "RCP_NOTHING_LIKE_IT is no setting of rcp (the settings are listed in the reference of the documentation)"
    )


def test_a_port_in_use_is_one_line_and_exit_2_before_anything_starts(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = rcp(tmp_path, "serve", "--port", str(port))
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and not run.stdout, run.stderr
    assert run.stderr.startswith(f"rcp: error: 127.0.0.1:{port}: Address already in use (--port or RCP_PORT"), (
        run.stderr
    )
    assert not (tmp_path / "xdg").exists()  # no data folder opened


def test_a_bad_host_on_the_command_line_is_named_as_the_option(tmp_path):
    run = rcp(tmp_path, "serve", "--host", "999.1.1.1", "--port", str(free_port()))
    assert run.returncode == 2 and run.stderr.count("\n") == 1, run.stderr
    assert run.stderr.startswith("rcp: error: --host 999.1.1.1: does not resolve"), run.stderr


def test_every_empty_setting_but_the_token_means_its_default_never_the_working_directory(tmp_path):
    """Every ``RCP_*`` variable set and empty (a deployment's variables left unset), the token aside: the server
    serves the bundled client and scenes, keeps its data in the user's data folder, asks no token; the working
    directory, with a secret file in it, is neither served nor written."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "secret.txt").write_text("the working directory's own")
    empty = {f"RCP_{name.upper()}": "" for name in Settings.model_fields if name != "token"}
    port = free_port()
    log = tmp_path / "serve.log"
    with log.open("w") as out:
        server = subprocess.Popen(
            [sys.executable, "-m", "rcp_server.cli", "serve", "--port", str(port)],
            cwd=work,
            env=environment(tmp_path, **empty),
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
        )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + READY_S
        while not _healthy(url):
            assert server.poll() is None and time.monotonic() < deadline, log.read_text()[-2000:]
            time.sleep(0.3)
        assert httpx.get(f"{url}/secret.txt").status_code == 404
        assert "<canvas" in httpx.get(f"{url}/").text  # the bundled client
        names = {scene["name"] for scene in httpx.get(f"{url}/api/scenes").json()}
        assert "default" in names  # the bundled scenes
        assert (tmp_path / "xdg" / "rcp" / "lock").exists()  # the user's data folder (XDG_DATA_HOME)
        assert [p.name for p in work.iterdir()] == ["secret.txt"]
    finally:
        server.send_signal(signal.SIGTERM)
        assert server.wait(60) == 0, log.read_text()[-2000:]
    assert "serving on http://127.0.0.1:" in log.read_text()  # RCP_HOST= is the default, loopback


def _healthy(url: str) -> bool:
    try:
        return httpx.get(f"{url}/api/health", timeout=2).status_code == 200
    except httpx.TransportError:
        return False


@pytest.mark.parametrize("given", [{"authorization": "Bearer"}, {"authorization": "Bearer "}, {}])
def test_an_empty_token_opens_nothing_even_where_one_got_past_the_settings(given):
    """Settings made without their checks (``model_construct``) and an empty token: nothing presented, an empty
    ``?token=`` or a bare ``Authorization: Bearer`` is still no token."""
    settings = Settings.model_construct(token=SecretStr(""))
    for query in ("", "token=", "token"):
        assert not admits(settings, Headers(given), QueryParams(query))
    assert admits(Settings.model_construct(token=SecretStr("t")), Headers({}), QueryParams("token=t"))
