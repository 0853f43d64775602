"""The service on a free loopback port, for the benchmarks (``rcp bench``) and the tests: ``BackgroundServer``
runs ``rcp serve`` in a thread of this process, ``rcp_serve`` runs it as a subprocess (so that its memory and
threads are its own), and ``rcp_environment`` is the environment such a subprocess runs in.

Also ``request``, a small HTTP client on the standard library: a plain install has no other.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from .server import Server
from .settings import Settings
from .state import service_of

TIMEOUT = 30.0  # the longest any single wait on a server may take (an answer, a stop)
START_TIMEOUT = 600.0  # a first start compiles the kernels: 30 s of one core, minutes on a busy machine
PACKAGE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding the rcp_server package
LOG_PROBLEM = re.compile(r"\b(WARNING|ERROR|CRITICAL|Traceback)\b")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


# ---- HTTP, with the standard library (a plain install has no HTTP client) ----


@dataclass(frozen=True)
class Answer:
    status: int
    content_type: str
    body: bytes


def request(url: str, body: dict | None = None, timeout: float = TIMEOUT, method: str | None = None) -> Answer:
    """GET ``url``, or POST ``body`` as JSON (or ``method``, such as DELETE), waiting at most ``timeout`` s; an
    error status is an answer too. Raises OSError when there is no answer (refused, reset, timed out)."""
    data = None if body is None else json.dumps(body).encode()
    headers = {} if data is None else {"content-type": "application/json"}
    asked = urllib.request.Request(url, data, headers, method=method)
    try:
        with urllib.request.urlopen(asked, timeout=timeout) as response:
            return Answer(response.status, response.headers.get("content-type", ""), response.read())
    except urllib.error.HTTPError as exc:
        with exc:
            return Answer(exc.code, exc.headers.get("content-type", ""), exc.read())


def get_json(url: str):
    """The JSON a GET of ``url`` answers, whatever its status."""
    return json.loads(request(url).body)


# ---- in this process ----


class BackgroundServer:
    """``rcp serve`` in a thread: uvicorn on 127.0.0.1 and a free port. Use it as a context manager."""

    def __init__(self, **settings):
        if "data" not in settings:  # a data folder of its own (the user's is never touched), removed at the end
            self._data = tempfile.TemporaryDirectory(prefix="rcp-data-")
            settings["data"] = Path(self._data.name)
        self.settings = Settings(host="127.0.0.1", port=free_port(), **settings)
        self.server = Server(self.settings, log_level="warning")
        self.app = self.server.app
        self.url = f"http://127.0.0.1:{self.settings.port}"
        self.ws_url = f"ws://127.0.0.1:{self.settings.port}/ws"
        self._thread = threading.Thread(target=self.server.run, name="rcp-server", daemon=True)

    def __enter__(self) -> BackgroundServer:
        self._thread.start()
        deadline = time.monotonic() + START_TIMEOUT
        while not (self.server.started and self.ready):  # listening, the scenes loaded, the kernels compiled
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the server did not start")
            time.sleep(0.05)
        return self

    @property
    def ready(self) -> bool:
        service = service_of(self.app)
        return service is not None and service.startup.ready

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self._thread.join(30)
        if hasattr(self, "_data"):
            self._data.cleanup()


# ---- a subprocess ----


@dataclass(frozen=True)
class ProcessSample:
    rss_mb: float  # resident set size, MiB
    threads: int


def process_sample(pid: int) -> ProcessSample:
    """RSS and thread count of a live process, from ``/proc/<pid>/status``."""
    fields = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        fields[key] = value.split()
    return ProcessSample(int(fields["VmRSS"][0]) / 1024, int(fields["Threads"][0]))


@dataclass
class Served:
    """A running ``rcp serve``: its process, its URLs and the file its log goes to."""

    process: subprocess.Popen
    port: int
    log: Path

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/ws"

    def sample(self) -> ProcessSample:
        return process_sample(self.process.pid)

    def log_problems(self) -> list[str]:
        """The log's warnings, errors and tracebacks (uvicorn's and rcp's), each line once in order."""
        lines = self.log.read_text(errors="replace").splitlines() if self.log.exists() else []
        return list(dict.fromkeys(line for line in lines if LOG_PROBLEM.search(line)))

    def stop(self) -> int | None:
        """SIGINT, as a terminal's Ctrl-C; the exit code, or None if it had to be killed."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
        try:
            return self.process.wait(TIMEOUT)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(TIMEOUT)
            return None


def _healthy(url: str) -> bool:
    try:
        return request(f"{url}/api/health", timeout=1).status == 200
    except OSError:  # refused while it starts
        return False


def rcp_environment(**settings: str) -> dict[str, str]:
    """This process's environment for an ``rcp`` subprocess, with ``settings`` as ``RCP_*`` variables (``token=``
    is ``RCP_TOKEN``): it runs the code this module was imported from, whatever the working directory, and its
    output is not buffered."""
    path = os.pathsep.join(filter(None, [str(PACKAGE_ROOT), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path, "PYTHONUNBUFFERED": "1"}
    env.update({f"RCP_{name.upper()}": value for name, value in settings.items()})
    return env


@contextlib.contextmanager
def rcp_serve(log_dir: Path, **settings: str):
    """``rcp serve`` in a subprocess on 127.0.0.1 and a free port (``settings`` as ``RCP_*`` variables: ``token=``
    is ``RCP_TOKEN``; without ``data=``, a new data folder in ``log_dir``), up once ``/api/health`` answers;
    stopped (or killed) on the way out."""
    settings.setdefault("data", tempfile.mkdtemp(prefix="data-", dir=log_dir))
    port = free_port()
    log = log_dir / "rcp-serve.log"
    command = [sys.executable, "-m", "rcp_server.cli", "serve", "--host", "127.0.0.1", "--port", str(port)]
    with log.open("w") as out:
        env = rcp_environment(**settings)
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env)
    served = Served(process, port, log)
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not _healthy(served.url):
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"rcp serve did not come up; its log:\n{log.read_text()[-2000:]}")
            time.sleep(0.2)
        yield served
    finally:
        served.stop()
