"""How every kernel is compiled, and how the slowest one compiles beside the others on a cold cache."""

from __future__ import annotations

import inspect
import pickle
import subprocess
import sys
import threading

import numba
from numba.core.registry import CPUDispatcher

# nogil: tiles run on threads side by side with Embree. No fast math: the kernels test for NaN rays on purpose,
# and a painting's recursion amplifies any reordering of float operations
# cache=True: compiled once per machine. numba's cache does not notice a change to a kernel that another kernel
# calls from another module: after editing one, remove ``rcp_server/**/__pycache__/*.nb[ci]`` (a fresh clone
# has none)
jit = numba.njit(nogil=True, cache=True, error_model="numpy")

BESIDE_WAIT_S = 300  # the longest a caller waits for the other process before it compiles the kernel itself
_CHILD = (
    "import importlib, pickle, sys; module, name, signature = pickle.load(sys.stdin.buffer); "
    "getattr(importlib.import_module(module), name).compile(signature)"
)
_beside: dict[CPUDispatcher, Beside] = {}
_lock = threading.Lock()


class Beside:
    """A kernel compiling into numba's cache in a process of its own, for one signature."""

    def __init__(self, kernel: CPUDispatcher, signature: tuple) -> None:
        command = [sys.executable, "-c", _CHILD]
        self.process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        assert self.process.stdin is not None
        with self.process.stdin as given:
            given.write(pickle.dumps((kernel.py_func.__module__, kernel.py_func.__name__, signature)))

    def wait(self) -> None:
        """Until it is in the cache (or the process failed: the caller then compiles it itself)."""
        try:
            self.process.wait(BESIDE_WAIT_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def compile_beside(kernel: CPUDispatcher, arguments: dict) -> Beside | None:
    """Start compiling ``kernel`` for the types of ``arguments`` (by keyword, as it will be called) in another
    process, into numba's cache, when neither this process nor the cache has it: a cold start then compiles
    it on the second core while this one compiles the kernels called before it. Call ``wait()`` on the answer
    before calling the kernel (which then loads it from the cache). None when there is nothing to compile."""
    if kernel.overloads:
        return None
    with _lock:
        if kernel in _beside:
            return _beside[kernel]
        bound = inspect.signature(kernel.py_func).bind(**arguments)
        signature = tuple(numba.typeof(value) for value in bound.args)
        if kernel._cache.load_overload(signature, kernel.targetctx) is not None:  # noqa: SLF001  numba's own check
            return None
        _beside[kernel] = Beside(kernel, signature)
        return _beside[kernel]
