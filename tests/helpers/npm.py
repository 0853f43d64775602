"""Packages from the npm registry that the client's tests need (``iwer`` for VR, ``typescript`` for the type
check), installed once per machine at a pinned version into a cache directory."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "rcp-tests"


def npm_package(name: str, version: str) -> Path:
    """The folder ``node_modules`` of ``name@version`` installed with npm under :data:`CACHE` (the first time:
    needs npm and the registry)."""
    home = CACHE / f"{name}-{version}"
    if not (home / "node_modules" / name / "package.json").is_file():
        npm = shutil.which("npm")
        assert npm, f"the test needs npm to install {name} (apt-get install npm, or Node.js with npm)"
        home.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f"{name}-", dir=home.parent))  # a worker's own: xdist runs two
        command = [npm, "install", "--prefix", str(staging), "--no-audit", "--no-fund", "--ignore-scripts"]
        subprocess.run([*command, f"{name}@{version}"], check=True, capture_output=True, timeout=600)
        try:
            staging.rename(home)
        except OSError:  # another worker got there first: its copy is the same
            shutil.rmtree(staging, ignore_errors=True)
    return home / "node_modules"
