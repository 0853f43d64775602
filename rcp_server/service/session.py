"""One WebSocket walk-through's I/O: messages in, painted frames out, the newest camera always wins.

The parts are elsewhere: what a message does to the view (``walkview.apply``, pure), what to paint next
(``planner.py``, pure), who paints (the painter port, ``painter.py``), and what waits (``outbox.py``: the newest
frame, the newest ``move`` and ``pick``, a rate). Here, four tasks share a session: the receiver applies
messages and bumps the planner's ``version`` (which abandons a refinement in flight), the painter paints what
the planner asks for, the asker answers questions one at a time, and the sender drains the outbox.
"""

from __future__ import annotations

import asyncio
import re
import time as _time
from collections.abc import Callable
from functools import partial
from typing import NamedTuple

from fastapi import WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from ..painting.loop import Abandoned
from ..scene.scene import Scene
from ..scene.scenefile import one_line
from ..settings.params import PaintParams
from . import protocol
from .asked import find_scene
from .faults import fault_message, report_fault
from .memory import admit
from .outbox import Outbox, Questions, Rate
from .planner import Planner
from .refusal import Refusal
from .state import Service
from .walkjobs import WalkJobs
from .walkview import Job, WalkView, another_picture, answer, apply

BURST_S = 4.0  # a walk-through may send this many seconds' worth of its message rate at once


def busy_message(limit: int, retry_s: int) -> str:
    """What a walk-through turned away for the server's ``max_sessions`` is told."""
    return f"the server is at its limit of {limit} walk-throughs; try again in {retry_s} s"


class Painting(NamedTuple):
    """A walk's painting as the memory budget counts it: its settings and its size, both eyes."""

    params: PaintParams
    width: int
    height: int


def painting_of(view: WalkView) -> Painting:
    assert view.params is not None and view.camera is not None, "after hello"
    return Painting(view.params, *view.camera.image_size(view.width, view.height))


def close_reason(line: str, limit: int = 120) -> str:
    """A close frame's reason, at most ``limit`` bytes (WebSocket allows 123): the line, or its start and its
    closing "try again in N s", which the page reads its time from."""
    if len(line.encode()) <= limit:
        return line
    found = re.search(r"; try again in \d+ s$", line)
    tail = found.group(0) if found else ""
    return line.encode()[: limit - len(tail) - 3].decode(errors="ignore") + "…" + tail


def hold_memory(service: Service, walker: object, before: WalkView, view: WalkView) -> None:
    """``walker``'s paintings hold their memory as ``view`` paints them (or :class:`~.memory.NoRoom`, a refusal);
    a smaller view gives the larger buffers back."""
    if view.params is None or (view.width, view.height, view.params) == (before.width, before.height, before.params):
        return
    held = service.memory.held(walker)
    admit(service.memory, walker, painting_of(view))
    if service.memory.held(walker) < held:
        service.painter.release(walker)


class Closing(Exception):
    """The session closes the socket: ``code`` and ``reason`` (the one error line it sent before)."""

    def __init__(self, code: int, reason: str, answering: str | None = None):
        super().__init__(reason)
        self.code, self.reason, self.answering = code, reason, answering  # answering: the message refused


class Session:
    def __init__(self, ws: WebSocket, service: Service):
        self.ws, self.service, self.settings, self.painter = ws, service, service.settings, service.painter
        self.view = WalkView()
        self.changed = asyncio.Event()
        settings = self.settings
        self.planner = Planner(settings.frame_ms, settings.settle_ms, settings.max_work, _time.monotonic())
        self.jobs = WalkJobs(self.planner)  # the frames asked for, and the last one shown
        self.closed = False
        self.outbox, self.questions = Outbox(), Questions()
        self.rate = Rate(settings.max_messages_per_s, BURST_S * settings.max_messages_per_s, _time.monotonic)

    @property
    def scene(self) -> Scene | None:
        """The scene it shows (None before hello)."""
        return self.view.scene

    @property
    def walking(self) -> bool:
        """Whether it has said hello: only then does it hold one of the server's ``max_sessions`` places."""
        return self.view.scene is not None

    async def run(self) -> None:
        try:
            async with asyncio.TaskGroup() as tasks:
                for task in (self._receive(), self._paint(), self._ask(), self._send(), self._expect_hello()):
                    tasks.create_task(task)
        except* WebSocketDisconnect:
            pass
        except* Closing as closing:
            first = closing.exceptions[0]
            assert isinstance(first, Closing)
            await self._send_now(first)
        finally:
            self.close()

    def close(self) -> None:
        """End the walk-through's painting: one still in flight stops at its next iteration."""
        self.closed = True
        self.painter.leave(self)
        self.service.memory.release(self)

    async def _send_now(self, closing: Closing) -> None:
        """The one error line, then the close with its reason (a client gone meanwhile is let be)."""
        try:
            line = protocol.Error.answering(closing.answering, closing.reason)
            await self._deliver({"type": "websocket.send", "text": line.model_dump_json()})
            await self.ws.close(code=closing.code, reason=close_reason(closing.reason))
        except Exception:  # gone already: nobody is left to tell
            pass

    async def _expect_hello(self) -> None:
        """A WebSocket that has not opened a walk-through within ``hello_timeout_s`` is let go (1008)."""
        seconds = self.settings.hello_timeout_s
        await asyncio.sleep(seconds)
        if self.view.scene is None:
            raise Closing(1008, f"no hello within {seconds:g} s")

    async def _receive(self) -> None:
        limit, rate = self.settings.max_message_bytes, self.settings.max_messages_per_s
        while True:
            message = await self.ws.receive()
            if message["type"] == "websocket.disconnect":
                raise WebSocketDisconnect(message.get("code", 1000))
            if not self.rate.allows():
                raise Closing(1008, f"more than {rate:g} messages a second (RCP_MAX_MESSAGES_PER_S)")
            text = message.get("text")
            if text is None:
                self.outbox.note(protocol.Error(message="send JSON text messages; binary messages mean nothing here"))
            elif len(text) > limit:
                self.outbox.note(protocol.Error(message=f"a message of {len(text)} characters; the limit is {limit}"))
            else:
                self._take(text)

    def _take(self, text: str) -> None:
        try:
            msg = protocol.client_message.validate_json(text)
        except ValidationError as exc:
            self.outbox.note(protocol.Error.answering(text, f"bad message: {one_line(exc)}"))
            return
        try:
            if isinstance(msg, protocol.MoveMessage | protocol.PickMessage):
                if self.view.scene is None:
                    raise Refusal(f"say hello first: a '{msg.type}' message needs a scene")
                self.questions.ask(msg)  # the newest of its kind replaces one still waiting
                return
            first = isinstance(msg, protocol.Hello) and self.view.scene is None
            if first and self.service.walking() >= self.settings.max_sessions:  # others said hello first
                retry_s = self.settings.walk_retry_s
                raise Refusal(busy_message(self.settings.max_sessions, retry_s), 503, retry_s)
            view = apply(self.view, msg, self.settings, partial(find_scene, self.service))
            if isinstance(view, Refusal):
                raise view
            hold_memory(self.service, self, self.view, view)
            if first and view.scene is not None and view.params is not None:  # its place with the painter
                self.painter.admit(self, view.params, view.scene)  # on Ray: while the cluster has room
            self._show(view)
        except Refusal as refusal:
            if isinstance(msg, protocol.Hello) and self.view.scene is None and refusal.retry_after is not None:
                raise Closing(1013, refusal.message, text) from None  # the page tries again after the time it states
            self.outbox.note(protocol.Error.answering(text, refusal.message))
        except Exception:  # a fault of ours: this message is lost, the session is not
            fault = fault_message(report_fault(f"session message {text[:200]!r}"))
            self.outbox.note(protocol.Error.answering(text, fault))

    def _show(self, view: WalkView) -> None:
        """Take ``view``: the planner, the kept state and the outbox follow what changed."""
        before, self.view = self.view, view
        now = _time.monotonic()
        if another_picture(before, view):
            self.jobs.kept = None  # the recursion starts again
        if view.epoch != before.epoch:
            self.planner.scene_started(now)
            self.outbox.drop_frame()  # a frame of the scene being left must not follow the new `ready`
            info = self.service.info(view.scene.name) if view.scene is not None else None
            ready = {"width": view.width, "height": view.height, "quality": view.quality}
            self.outbox.note(
                protocol.Ready(scene=info, temporal=view.temporal, animate=view.animate, **ready)  # type: ignore[arg-type]
            )
        elif view.camera is not before.camera:
            self.planner.camera_moved(now)
        self.planner.view_changed()
        self.changed.set()

    # ---- painting and answering ----

    async def _paint(self) -> None:
        while True:
            job = self.jobs.next(self.view, _time.monotonic())
            if job is None:
                self.changed.clear()
                wait = (
                    None if self.view.scene is None else self.planner.until_rest(_time.monotonic(), self.view.planned())
                )
                try:
                    async with asyncio.timeout(wait):
                        await self.changed.wait()
                except TimeoutError:
                    pass
                continue
            try:
                run = partial(self.painter.walk_frame, self, job.frame, self._stop(job))
                painted = await self.service.workshop.run(run)
            except Abandoned:
                if self.service.workshop.stopping:
                    return  # the server is stopping: nothing will paint again
                continue
            except Exception as exc:  # this view cannot be painted: say why, and wait for the next change
                self.planner.frame_failed(job.plan, self.view.planned())
                message = str(exc) if isinstance(exc, ValueError | Refusal) else None  # CameraError among them
                where = f"painting {job.plan.phase} frame"
                self.outbox.note(protocol.Error(message=message or fault_message(report_fault(where))))
                continue
            if job.epoch == self.view.epoch:  # else painted for a scene the client has left
                self.outbox.post_frame(*self.jobs.finished(job, painted, self.view.width))

    def _stop(self, job: Job) -> Callable[[], bool]:
        """Refinements are abandoned as soon as anything changes; walk frames are short by design and always
        finish, or a camera that never rests would never see a frame."""
        plan = job.plan

        def should_stop() -> bool:
            stale = self.planner.version != plan.version if plan.phase == "refine" else self.view.epoch != job.epoch
            return self.closed or stale

        return should_stop

    async def _ask(self) -> None:
        """Answer the questions, one at a time (milliseconds of rays in a big scene: off the event loop)."""
        while True:
            question = await self.questions.next()
            try:
                self.outbox.note(await asyncio.to_thread(answer, self.view, self.jobs.shown_time, question))
            except ValueError as exc:  # CameraError among them
                self.outbox.note(protocol.Error(message=str(exc)))
            except Exception:  # a fault of ours: this question is lost, the session is not
                self.outbox.note(protocol.Error(message=fault_message(report_fault(f"answering a {question.type}"))))

    # ---- sending ----

    async def _send(self) -> None:
        while True:
            for message in await self.outbox.take():
                await self._deliver(message)

    async def _deliver(self, message: dict) -> None:
        """A send waits while the client's buffers are full (newer frames replace the unsent one meanwhile);
        a client that takes nothing for ``send_timeout_s`` has gone and is let go."""
        try:  # asyncio.timeout, not wait_for: 3.11's wait_for may swallow the task group's cancel as a send ends
            async with asyncio.timeout(self.settings.send_timeout_s):
                await self.ws.send(message)
        except TimeoutError:
            raise WebSocketDisconnect(1001, "the client took no data") from None
