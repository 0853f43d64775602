"""Where paintings are made off the event loop: the workers, the places, and the door.

The engine paints; this module only queues and admits its work. A painting blocks while its tiles run, so
each one waits on a thread of its own (at most ``max_renders`` at once); its tiles go to the shared
:class:`FairPool`. The pool serves tiles by their position in their painting, so paintings in progress take
turns tile by tile: a small walk-through frame is not stuck behind every tile of a large render that came
first. A video's tiles go in the pool's background lane: they take only the cores that walks and REST
renders leave, and a walk's tile waits at most for the video tiles already in progress. REST renders are
admitted at the door (:meth:`Workshop.admission`) or turned away (:func:`busy`).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math
import queue
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from functools import partial
from typing import TypeVar

from ..painting.loop import paint
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .refusal import Refusal

T = TypeVar("T")


FOREGROUND, BACKGROUND = 0, 1  # a FairPool's lanes: what someone is watching, and what can wait (videos)


class FairPool(Executor):
    """Worker threads that take the task with the lowest (lane, position in its batch, arrival) first: a
    background task starts only while no foreground task waits (one in progress keeps its thread)."""

    def __init__(self, workers: int, name: str = "rcp-tile"):
        self._tasks: queue.PriorityQueue = queue.PriorityQueue()
        self._arrival = itertools.count()
        self._threads = [threading.Thread(target=self._work, name=f"{name}-{k}", daemon=True) for k in range(workers)]
        self._foreground = Lane(self, FOREGROUND)
        self.background = Lane(self, BACKGROUND)  # the same threads, for work nobody is waiting to see
        for thread in self._threads:
            thread.start()

    def put(self, lane: int, position: int, fn: Callable, args: tuple) -> Future:
        """Queue ``fn(*args)`` in ``lane`` at ``position`` of its batch."""
        future: Future = Future()
        self._tasks.put(((lane, position), next(self._arrival), future, fn, args))
        return future

    def submit(self, fn, /, *args, **kwargs) -> Future:
        return self._foreground.submit(fn, *args, **kwargs)

    def map(self, fn: Callable[..., T], *iterables: Iterable, timeout=None, chunksize=1) -> Iterator[T]:
        return self._foreground.map(fn, *iterables, timeout=timeout)

    def _work(self) -> None:
        while True:
            _, _, future, fn, args = self._tasks.get()
            if future is None:
                return
            if not future.set_running_or_notify_cancel():
                continue
            try:
                future.set_result(fn(*args))
            except BaseException as exc:  # handed to whoever waits on the future
                future.set_exception(exc)
            # an idle thread would otherwise keep its last tile's task, and with it that whole painting's buffers
            del future, fn, args

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        for _ in self._threads:
            self._tasks.put(((BACKGROUND + 1, 0), next(self._arrival), None, None, None))
        if wait:
            for thread in self._threads:
                thread.join()


class Lane(Executor):
    """A lane of a :class:`FairPool`, as an executor to paint on (``painting.paint``); the pool itself is its
    foreground lane."""

    def __init__(self, pool: FairPool, lane: int):
        self._pool = pool
        self._lane = lane

    def submit(self, fn, /, *args, **kwargs) -> Future:
        return self._pool.put(self._lane, 0, partial(fn, **kwargs), args)

    def map(self, fn: Callable[..., T], *iterables: Iterable, timeout=None, chunksize=1) -> Iterator[T]:
        futures = [self._pool.put(self._lane, k, fn, args) for k, args in enumerate(zip(*iterables, strict=True))]

        def results() -> Iterator[T]:
            try:
                for future in futures:
                    yield future.result(timeout)
            finally:  # a failed or abandoned painting takes its queued tiles with it
                for future in futures:
                    future.cancel()

        return results()


def busy(retry_after: int) -> Refusal:
    """Every render slot and waiting place is taken (503); ``retry_after`` is a fair guess in seconds."""
    return Refusal(f"the server is busy with other renders; try again in {retry_after} s", 503, retry_after)


class Workshop:
    """Runs paintings (and whatever goes with them, such as encoding) off the event loop, on shared workers.

    Walk-throughs are limited by their count (one painting each at a time); REST renders are admitted up
    to ``max_renders + max_waiting`` at once, and past that refused (:func:`busy`) rather than queued
    without bound."""

    def __init__(self, threads: int, max_renders: int, max_waiting: int = 0):
        self.threads = threads
        self.tiles = FairPool(threads)
        self._painters = ThreadPoolExecutor(max_renders, thread_name_prefix="rcp-render")  # one painting each
        self._places = max_renders + max_waiting
        self.admitted = 0  # REST renders running or waiting
        self.in_progress = 0  # paintings in progress, of any kind
        self._counting = threading.Lock()  # paintings start and end on many threads
        self._seconds = 1.0  # recent REST render time, for Retry-After
        self.stopping = False  # see stop()

    def paint(
        self,
        scene: Scene,
        camera,
        width: int,
        height: int,
        params: PaintParams,
        should_stop=None,
        background: bool = False,
        **options,
    ):
        """Blocking: paint on the shared tile pool (call it inside :meth:`run`); ``background`` (a video's
        frames), only on the cores the walk-throughs and REST renders leave. Every painting stops at its next
        tile once the workshop stops."""

        def stop() -> bool:
            return self.stopping or (should_stop is not None and should_stop())

        with self._counting:
            self.in_progress += 1
        try:
            return paint(
                scene,
                camera,
                width,
                height,
                params,
                pool=self.tiles.background if background else self.tiles,
                threads=self.threads,
                should_stop=stop,
                **options,
            )
        finally:
            with self._counting:
                self.in_progress -= 1

    async def run(self, job: Callable[[], T]) -> T:
        """``job()`` on a painter's thread, awaited from the event loop."""
        return await asyncio.get_running_loop().run_in_executor(self._painters, job)

    @contextlib.contextmanager
    def admission(self) -> Iterator[None]:
        """A REST render's place: raises the :func:`busy` refusal when there is none, else holds one while it runs."""
        if self.admitted >= self._places:
            raise busy(max(1, math.ceil(self._seconds * self.admitted / self._places)))
        self.admitted += 1
        clock = time.monotonic()
        try:
            yield
        finally:
            self.admitted -= 1
            self._seconds = 0.7 * self._seconds + 0.3 * (time.monotonic() - clock)

    def stop(self) -> None:
        """Stop every painting at its next tile (each raises :class:`~rcp_server.painting.loop.Abandoned`), and any
        that starts from now on at once: the server is stopping."""
        self.stopping = True

    def close(self) -> None:
        self.stop()
        self._painters.shutdown(wait=True, cancel_futures=True)
        self.tiles.shutdown(wait=True)
