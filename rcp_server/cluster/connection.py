"""Joining Ray and backing off after it failed: the errors that say why Ray cannot be used, an address checked
in bounded time, and when Ray is tried again.

Ray is the ``cluster`` extra: this module imports it only once asked to (:func:`ray_module`).
"""

from __future__ import annotations

import logging
import math
import os
import signal
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

CONNECT_TIMEOUT_S = 10.0
"""How long an address may take to answer at all before we say it does not (``ray.init`` itself retries a
silent address for minutes)."""
JOIN_RETRY_S = 1.0  # joining at start-up: how often an address that does not answer yet is asked again
BACKOFF_FIRST_S = 5.0  # after a Ray failure, Ray is not tried for this long; doubled at each failure in a row
BACKOFF_MOST_S = 300.0
GCS_PATIENCE_S = 7 * 24 * 3600
"""How long this process outlives its cluster's head (Ray's ``gcs_rpc_server_reconnect_timeout_s``): by default
Ray ends the whole driver after 60 s without its GCS, and a server must go on painting here meanwhile (seen: the
process killed at 60 s; with this, alive at 75 s)."""


class ClusterError(RuntimeError):
    """Ray cannot be used as asked (not installed, an address that does not answer, a worker lost); one line."""


@dataclass
class Backoff:
    """When to try Ray again after it failed: not for ``first_s``, doubled at each failure in a row up to
    ``most_s``; a success starts again from nothing. A policy of clocks and counters (``clock`` is a fake one in
    tests): the painter asks it, and fails at once while it says wait."""

    first_s: float = BACKOFF_FIRST_S
    most_s: float = BACKOFF_MOST_S
    clock: Callable[[], float] = time.monotonic
    failures: int = 0
    until: float = 0.0
    reason: str = ""

    def failed(self, reason: str) -> None:
        self.failures += 1
        self.until = self.clock() + min(self.most_s, self.first_s * 2 ** (self.failures - 1))
        self.reason = reason

    def succeeded(self) -> None:
        self.failures, self.until, self.reason = 0, 0.0, ""

    def wait_s(self) -> float:
        """Seconds before Ray may be tried again (0: now)."""
        return max(0.0, self.until - self.clock())


class PaintingFailed(ClusterError):
    """A painting raised on a worker: a fault of the painting, not of Ray (asking again would fail again)."""


class Unanswered(ClusterError):
    """Nothing answers at the address (yet: a head that is starting answers in a moment)."""


def ray_module():
    """Ray, imported on first use; :class:`ClusterError` when the ``cluster`` extra is not installed."""
    try:
        import ray
    except ImportError:
        raise ClusterError("Ray is not installed: pip install 'rcp-server[cluster]'") from None
    return ray


def check_address(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Raises :class:`ClusterError` unless ``address`` (``host:port``, ``ray://host:port``) takes a TCP
    connection within ``timeout_s``: a bounded answer for an address that is wrong or down."""
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if not host or not port:
        raise ClusterError(f"Ray address {address!r} is not host:port or ray://host:port")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        reason = f"no answer within {timeout_s:g} s" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise Unanswered(f"Ray address {address} does not answer ({reason})") from None


def connect(address: str | None = None, num_cpus: int | None = None, **local_options) -> bool:
    """Join the Ray cluster at ``address`` (or ``RAY_ADDRESS``), else (or with ``local``) start a Ray runtime of
    this process's own on this machine, never joining one it finds there
    (``num_cpus``, ``local_options`` for ``ray.init``). Returns whether this call started Ray (then the caller
    shuts it down). An address is checked first (:func:`check_address`); every fault is a :class:`ClusterError`."""
    ray = ray_module()
    # "local" is a runtime of this process's own, never one found on this machine (a dead one's address lingers)
    address = address or os.environ.get("RAY_ADDRESS") or "local"
    if address not in ("local", "auto"):
        check_address(address)
    if ray.is_initialized():  # joined already (a test's runtime, an earlier job): it stays as it is
        return False
    # read by the driver's core worker as it starts (an operator's own setting wins)
    os.environ.setdefault("RAY_gcs_rpc_server_reconnect_timeout_s", str(GCS_PATIENCE_S))
    options: dict[str, Any] = {"log_to_driver": False, "configure_logging": False}
    if address == "local":
        options |= {"include_dashboard": False, "num_cpus": num_cpus, **local_options}
    # ray.init puts its own SIGTERM handler in place (exit status 15) on the main thread: the caller's stays
    stop = signal.getsignal(signal.SIGTERM) if threading.current_thread() is threading.main_thread() else None
    try:
        ray.init(address=address, **options)
    except Exception as exc:  # Ray's own errors are many and long: the first line says enough
        where = "" if address == "local" else f" at {address}"
        raise ClusterError(f"cannot start Ray{where}: {first_line(exc)}") from None
    finally:
        if callable(stop):  # one the caller set (rcp serve's: a stop asked for is exit 0), not the default
            signal.signal(signal.SIGTERM, stop)
    return True


def first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def worker_failure(exc) -> str:
    """What failed on a Ray worker, in one line: the worker's exception type and the first line of its message
    (a ``RayTaskError``'s own first line names only the remote call, ``ray::Painter.band()``)."""
    cause = getattr(exc, "cause", None)
    if not isinstance(cause, BaseException):
        return first_line(exc)
    text = str(cause).strip()
    return f"{type(cause).__name__}: {text.splitlines()[0]}" if text else type(cause).__name__


class Connection:
    """This process joined to Ray (``address``: as :func:`connect`), and the :class:`Backoff` after a failure:
    what every kind of painting on Ray shares."""

    def __init__(self, address: str | None = None, num_cpus=None):
        self.address = address
        self.backoff = Backoff()
        self.lock = threading.Lock()
        self._num_cpus = num_cpus
        self.started = False  # this process started Ray: it shuts it down
        self.connected = False
        self.generation = 0  # counts the joins: actors and objects of an earlier one are gone

    def start(self, timeout_s: float | None = None) -> None:
        """Join (or start) Ray now, rather than with the first painting; raises :class:`ClusterError`. With
        ``timeout_s``, an address that does not answer is asked again every ``JOIN_RETRY_S`` (a head starting
        beside us answers in a moment) until then, and one that takes connections but never joins (not Ray's)
        is given up then."""
        if timeout_s is None or self.address in (None, "", "local"):
            # a runtime of our own is started on this thread: Ray's processes die with the thread that started them
            with self.lock:
                self.join()
            return
        # joined on a thread of its own, so that it can be given up; Ray then leaves SIGTERM to us (a server stops
        # gracefully on it) and says so in a warning that is no news: filtered out
        logging.getLogger("ray._private.worker").addFilter(_NoSigtermNote())
        deadline = time.monotonic() + timeout_s
        outcome: list[BaseException | None] = []
        unanswered: list[Unanswered] = []

        def join() -> None:
            while True:  # an address nobody answers at yet (a head pod starting beside us) is asked again
                failure = _failure(self.start)
                if not isinstance(failure, Unanswered) or time.monotonic() + JOIN_RETRY_S > deadline:
                    outcome.append(failure)
                    return
                unanswered[:] = [failure]
                time.sleep(JOIN_RETRY_S)

        joiner = threading.Thread(target=join, name="rcp-ray-join", daemon=True)
        joiner.start()
        joiner.join(max(0.0, deadline - time.monotonic()))
        if not outcome:
            if unanswered:
                raise unanswered[0]
            raise ClusterError(f"Ray at {self.address} was not joined within {timeout_s:g} s (RCP_RAY_JOIN_S)")
        if outcome[0] is not None:
            raise outcome[0]

    def join(self) -> None:
        """Joined (or started) Ray, once; call it holding :attr:`lock`."""
        if not self.connected:
            self.started = connect(self.address, self._num_cpus)
            self.connected = True
            self.generation += 1

    def gone(self) -> bool:
        """Whether Ray went away under us (its runtime stopped): then the next try joins it afresh."""
        if self.connected and not ray_module().is_initialized():
            with self.lock:
                self.connected = False
        return not self.connected

    def ready(self) -> bool:
        """Whether Ray may be tried now (not backing off after a failure)."""
        return self.backoff.wait_s() == 0

    def check(self) -> None:
        """Raises :class:`ClusterError` while Ray backs off after a failure."""
        wait = self.backoff.wait_s()
        if wait > 0:
            raise ClusterError(f"{self.backoff.reason} (Ray is tried again in {math.ceil(wait)} s)")

    def close(self) -> None:
        """Stop Ray if this process started it."""
        if self.started:
            ray_module().shutdown()
        self.connected = False


class _NoSigtermNote(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "SIGTERM handler is not set" not in record.getMessage()


def _failure(call: Callable[[], Any]) -> BaseException | None:
    """What ``call()`` raised, None if nothing."""
    try:
        call()
    except BaseException as exc:  # handed to the thread that waits for it
        return exc
    return None
