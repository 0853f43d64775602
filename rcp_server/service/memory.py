"""Memory as a resource the server admits: the paintings' per-pixel buffers held against one budget
(``RCP_MEMORY_BYTES``), and the memory of those that ended given back to the system.

A walk-through holds its share from its ``hello`` until it closes (and again, resized, at every change of its
size or settings); a REST render holds its own while it paints; a film or a print waits for its own, then holds it
while it paints. The share is what the painting declares a
pixel costs (``painting/workspace.py::pixel_bytes``) times its pixels (both eyes of a stereo pair): a painting
that can never fit is refused for good, one that does not fit beside the others now is told to try again.

:class:`Budget` is a pure account of bytes (no clock, no I/O); :func:`give_back` and :class:`GiveBack` return
what closed walks freed to the system: a walk's buffers are gone once no painting uses them, but the C
allocator keeps the pages of many small and middling arrays (a tile's, a few hundred kB each) for itself unless
asked (glibc's ``malloc_trim``).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import math
import threading
import weakref
from collections.abc import Callable, Hashable, Iterator
from pathlib import Path
from typing import Protocol, TypeVar

from ..painting.workspace import pixel_bytes
from ..settings.params import PaintParams
from .refusal import Refusal

MB = 1 << 20
SHARE_OF_THE_MACHINE = 0.5  # the default budget: this much of the memory the machine (or container) has left
RETRY_AFTER_S = 5  # a painting that does not fit beside the others now: about one walk frame's refinement
WALK_KEEPS = 2  # a walk's workspace alternates two results: the frame shown (kept for temporal mode) and the next


class NoRoom(Refusal):
    """A painting the budget has no room for, in one line: 503 with ``retry_after`` (s) when it would fit once
    others end; 422 when it can never fit (then the caller must ask for less)."""

    def __init__(self, message: str, retry_after: int | None):
        super().__init__(message, 422 if retry_after is None else 503, retry_after)


def painting_bytes(params: PaintParams, width: int, height: int, kept: int = 1) -> int:
    """The bytes a painting of ``width x height`` pixels (both eyes) with ``params`` holds, by the declared bytes a
    pixel; the ink of outlines and the anchor of shared eyes are counted whether they are drawn or not (a bound,
    for a few bytes a pixel)."""
    per_pixel = pixel_bytes(params, outlines=True, shared=True, kept=kept)
    return width * height * sum(per_pixel.values())


class Sized(Protocol):
    """A painting a door let through (``asked.Asked``): its settings and its size, both eyes."""

    @property
    def params(self) -> PaintParams: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...


P = TypeVar("P", bound=Sized)


def admit(budget: Budget, holder: Hashable, painting: P, what: str = "a walk-through") -> P:
    """``painting``, once ``holder`` (a walk-through) holds what it takes, kept results included, in place of what
    it held; else :class:`NoRoom`, and it holds what it held."""
    size = (painting.width, painting.height)
    budget.reserve(holder, painting_bytes(painting.params, *size, kept=WALK_KEEPS), size, what)
    return painting


def mb(nbytes: int) -> str:
    return f"{nbytes / MB:,.0f} MB" if nbytes >= 10 * MB else f"{nbytes / MB:.1f} MB"


class Budget:
    """Bytes held against ``total``, by holder (a walk-through, a render): a pure account, safe across threads."""

    def __init__(self, total: int):
        self.total = total
        self._held: dict[Hashable, int] = {}
        self._lock = threading.Lock()

    @property
    def used(self) -> int:
        with self._lock:
            return sum(self._held.values())

    def held(self, holder: Hashable) -> int:
        with self._lock:
            return self._held.get(holder, 0)

    def reserve(self, holder: Hashable, nbytes: int, size: tuple[int, int], what: str) -> None:
        """Hold ``nbytes`` for ``holder`` in place of what it held, or raise :class:`NoRoom` (and hold what it held
        before). ``size`` (width, height) is the painting's, for the smaller one the refusal offers."""
        with self._lock:
            others = sum(self._held.values()) - self._held.get(holder, 0)
            room = self.total - others
            if nbytes <= room:
                self._held[holder] = nbytes
                return
        self.check(nbytes, size, what)
        raise NoRoom(
            f"{what} of {size[0]}x{size[1]} pixels needs {mb(nbytes)} of memory; the paintings in progress leave "
            f"{mb(max(0, room))} of the {mb(self.total)} (RCP_MEMORY_BYTES): {smaller(size, nbytes, room)}, or try "
            f"again in {RETRY_AFTER_S} s",
            RETRY_AFTER_S,
        )

    def check(self, nbytes: int, size: tuple[int, int], what: str) -> None:
        """:class:`NoRoom` (422) if ``nbytes`` could never fit, whatever else ends."""
        if nbytes > self.total:
            raise NoRoom(
                f"{what} of {size[0]}x{size[1]} pixels needs {mb(nbytes)} of memory, more than the {mb(self.total)} "
                f"all paintings may take (RCP_MEMORY_BYTES): {smaller(size, nbytes, self.total)}",
                None,
            )

    def release(self, holder: Hashable) -> int:
        """Give back what ``holder`` held; the bytes it held (0: nothing)."""
        with self._lock:
            return self._held.pop(holder, 0)

    @contextlib.contextmanager
    def reserved(self, nbytes: int, size: tuple[int, int], what: str) -> Iterator[None]:
        """``nbytes`` held for the ``with`` block (a render), or :class:`NoRoom`."""
        holder = object()
        self.reserve(holder, nbytes, size, what)
        try:
            yield
        finally:
            self.release(holder)


def wait_for_room(
    budget: Budget, holder: Hashable, nbytes: int, size: tuple[int, int], what: str, cancelled: threading.Event,
    waiting: Callable[[str], None],
) -> bool:  # fmt: skip
    """Hold ``nbytes`` for ``holder`` (a film or a print: a background job nobody waits on to be refused) once
    they fit beside the other paintings, saying why it waits through ``waiting`` meanwhile: True once held, False
    if ``cancelled`` first; :class:`NoRoom` (422) if they can never fit."""
    while True:
        try:
            budget.reserve(holder, nbytes, size, what)
            return True
        except NoRoom as refusal:
            if refusal.retry_after is None:
                raise
            waiting(refusal.message)
            if cancelled.wait(refusal.retry_after):
                return False


def smaller(size: tuple[int, int], nbytes: int, room: int) -> str:
    """The offer of a refusal: the largest painting of the same shape that fits in ``room`` bytes."""
    scale = math.sqrt(max(0, room) / nbytes)
    width, height = math.floor(size[0] * scale), math.floor(size[1] * scale)
    return f"at most {width}x{height} would fit" if width and height else "nothing fits now"


# ---- the machine's memory ----


def machine_memory() -> int:
    """Bytes this process may still take: the kernel's ``MemAvailable``, or the room left under the container's
    limit (cgroup v2's ``memory.max`` less ``memory.current``, or v1's) when that is less."""
    available = _meminfo("MemAvailable") or _meminfo("MemTotal") or 1 << 30
    for limit, usage in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
    ):
        bound, used = _number(limit), _number(usage)
        if bound is not None and bound < 1 << 60:  # "max", or v1's huge number: no limit
            available = min(available, max(0, bound - (used or 0)))
            break
    return available


def default_memory_bytes() -> int:
    """``RCP_MEMORY_BYTES``' default: a share of what the machine (or container) has left as the server starts,
    at least 256 MB."""
    return max(256 * MB, int(machine_memory() * SHARE_OF_THE_MACHINE))


def _meminfo(key: str) -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            name, _, value = line.partition(":")
            if name == key:
                return int(value.split()[0]) * 1024  # kB
    except (OSError, ValueError, IndexError):
        pass
    return None


def _number(path: str) -> int | None:
    try:
        return int(Path(path).read_text().strip())
    except (OSError, ValueError):  # missing, or "max"
        return None


# ---- giving memory back ----

_LIBC = ctypes.util.find_library("c")


def malloc_trim() -> bool:
    """Return the C heap's free pages to the system (glibc's ``malloc_trim(0)``, every arena); False where there
    is no such call (another C library)."""
    try:
        trim = ctypes.CDLL(_LIBC).malloc_trim if _LIBC else None
    except (OSError, AttributeError):
        return False
    if trim is None:
        return False
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    trim(0)
    return True


def give_back() -> None:
    """Blocking (a few ms): return the free heap to the system. No garbage collection first: measured, it gave
    back nothing more (``rcp bench``-style walks of a million pixels, four at once: 745 MB at their peak, 382 MB
    after they closed with the trim alone, 381 MB with a collection before it, 582 MB with neither, 356 MB
    before the walks), and a full collection holds every thread for tens of ms."""
    malloc_trim()


class GiveBack:
    """A thread that gives memory back (:func:`give_back`) once the buffers of a closed walk are gone: ``after(x)``
    asks for it when ``x`` (the walk's workspace) is no longer referenced, which is once the walk's last painting
    has stopped, and at once too (what it held outside its paintings). Requests that come together are served
    once."""

    def __init__(self) -> None:
        self._due = threading.Event()
        self._closed = False
        self.given = 0  # times memory was given back
        self._thread = threading.Thread(target=self._run, name="rcp-give-back", daemon=True)
        self._thread.start()

    def after(self, *gone: object) -> None:
        for item in gone:
            weakref.finalize(item, self._due.set)
        self._due.set()

    def _run(self) -> None:
        while True:
            self._due.wait()
            if self._closed:
                return
            self._due.clear()
            give_back()
            self.given += 1

    def close(self) -> None:
        self._closed = True
        self._due.set()
