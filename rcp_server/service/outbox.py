"""A walk-through's bounds on what waits, both ways (viser's ``AsyncMessageBuffer``): what the server sends
(:class:`Outbox`: notes in order, and one slot for the newest of each kind: a frame not yet sent is replaced by
a newer one), what a client asks (:class:`Questions`: the newest ``move`` and ``pick``, one answered at a time)
and how fast it may ask (:class:`Rate`)."""

from __future__ import annotations

import asyncio
import collections
from collections.abc import Callable

from pydantic import BaseModel

from . import protocol

NOTES = 64  # text messages kept for a slow client; older ones go first


class Outbox:
    """What waits to be sent: notes in order (at most ``NOTES``), then the newest frame (its text and its JPEG)."""

    def __init__(self) -> None:
        self.notes: collections.deque[str] = collections.deque(maxlen=NOTES)
        self.frame: tuple[str, list[bytes]] | None = None  # its text, and its JPEG (or its bands', in order)
        self.seq = 0  # frames posted
        self.dropped = 0  # frames replaced before they were sent
        self.ready = asyncio.Event()

    def note(self, message: BaseModel) -> None:
        self.notes.append(message.model_dump_json())
        self.ready.set()

    def post_frame(self, meta: protocol.Frame, jpegs: list[bytes]) -> None:
        if self.frame is not None:
            self.dropped += 1  # never sent: this newer frame replaces it
        self.seq += 1
        self.frame = (meta.model_copy(update={"seq": self.seq, "dropped": self.dropped}).model_dump_json(), jpegs)
        self.ready.set()

    def drop_frame(self) -> None:
        """Forget the frame not yet sent (it shows a scene the client has left)."""
        self.frame = None

    async def take(self) -> list[dict]:
        """The ASGI messages to send next, once there are any: the notes, then the frame's text and JPEG."""
        await self.ready.wait()
        self.ready.clear()
        messages: list[dict] = [{"type": "websocket.send", "text": text} for text in self.notes]
        self.notes.clear()
        if self.frame is not None:
            (text, jpegs), self.frame = self.frame, None
            messages += [{"type": "websocket.send", "text": text}]
            messages += [{"type": "websocket.send", "bytes": jpeg} for jpeg in jpegs]  # as the workers encoded them
        return messages


Question = protocol.MoveMessage | protocol.PickMessage


class Questions:
    """The questions waiting for an answer: the newest of each kind (a waiting ``move`` is replaced by a newer
    one, as a waiting camera is), taken one at a time by the one task that answers them."""

    def __init__(self) -> None:
        self.waiting: dict[str, Question] = {}
        self.replaced = 0
        self.ready = asyncio.Event()

    def ask(self, question: Question) -> None:
        if question.type in self.waiting:
            self.replaced += 1
        self.waiting[question.type] = question
        self.ready.set()

    async def next(self) -> Question:
        while not self.waiting:
            self.ready.clear()
            await self.ready.wait()
        kind = next(iter(self.waiting))
        return self.waiting.pop(kind)


class Rate:
    """A token bucket: ``per_s`` messages a second on average, ``burst`` at once; ``clock``: seconds."""

    def __init__(self, per_s: float, burst: float, clock: Callable[[], float]):
        self.per_s, self.burst, self.clock = per_s, burst, clock
        self.tokens, self.last = burst, clock()

    def allows(self) -> bool:
        """Whether one more message is within the rate (it is counted)."""
        now = self.clock()
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.per_s)
        self.last = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True
