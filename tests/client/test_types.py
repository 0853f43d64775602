"""The client's types: every module says ``// @ts-check``, and TypeScript's compiler (from the npm registry, at a
pinned version) finds no error in them with ``client/jsconfig.json``. No browser needed."""

from __future__ import annotations

import subprocess

from helpers.npm import npm_package

from rcp_server.service.settings import REPOSITORY

TYPESCRIPT_VERSION = "5.9.3"
CLIENT = REPOSITORY / "client"


def test_every_client_module_asks_to_be_type_checked():
    modules = sorted(CLIENT.glob("*.js")) + sorted(CLIENT.glob("path/*.js"))
    unchecked = [str(m.relative_to(CLIENT)) for m in modules if "// @ts-check" not in m.read_text()]
    assert not unchecked


def test_the_client_type_checks():
    tsc = npm_package("typescript", TYPESCRIPT_VERSION) / "typescript" / "bin" / "tsc"
    done = subprocess.run(
        ["node", str(tsc), "-p", str(CLIENT / "jsconfig.json")], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout + done.stderr
