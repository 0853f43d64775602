"""One WebSocket walk-through: camera in, painted frames out, the newest camera always wins.

Three tasks share a session. The receiver validates messages and updates the view; every change bumps the
planner's ``version``, which abandons a refinement in flight between iterations. The painter asks the
:class:`~rcp_server.service.planner.Planner` what to paint next (walk frames while the camera moves,
refinements once it rests), paints it on the workshop and tells the planner how long it took. The sender
keeps one slot for frames: a frame not yet sent is replaced by a newer one, so a slow client never gets a
queue of stale frames.
"""

from __future__ import annotations

import asyncio
import base64
import collections
import logging
import math
import time as _time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from fastapi import WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from ..camera.camera import Camera, CameraError
from ..camera.wire import camera_of
from ..media.walkframe import WalkFrame, WalkPainted
from ..painting.loop import Abandoned
from ..painting.raytrace import object_pixels, pick
from ..scene.scene import Scene
from ..scene.scenefile import one_line
from ..scene.walking import walk
from ..settings.params import PaintParams
from . import protocol
from .asked import asked, check
from .faults import fault_message, report_fault
from .planner import Plan, Planner, View, frame_quality
from .refusal import Refusal
from .state import Service

log = logging.getLogger("rcp.service")

MASK_PIXELS = 160 * 90 * 4  # a picked object's outline is traced at most this fine (a few ms of rays)


def pick_mask(scene: Scene, time: float, camera: Camera, size: tuple[int, int], name: str) -> protocol.PickMask:
    """Where object ``name`` shows in a view of ``size`` (width, height), at most ``MASK_PIXELS`` fine."""
    scale = min(1.0, math.sqrt(MASK_PIXELS / (size[0] * size[1])))
    width, height = max(1, round(size[0] * scale)), max(1, round(size[1] * scale))
    shows = object_pixels(scene, time, camera, width, height, name)
    bits = base64.b64encode(np.packbits(shows.reshape(-1)).tobytes()).decode()
    return protocol.PickMask(width=width, height=height, bits=bits)


def busy_message(limit: int) -> str:
    """What a walk-through turned away for the server's ``max_sessions`` is told."""
    return f"the server is at its limit of {limit} walk-throughs; try again later"


@dataclass(frozen=True)
class Job:
    """One frame to paint: the planner's plan, the frame as the painter takes it, and the view it shows."""

    plan: Plan
    epoch: int
    camera_id: int | None
    frame: WalkFrame


class Session:
    def __init__(self, ws: WebSocket, service: Service):
        self.ws, self.service, self.workshop, self.settings = ws, service, service.workshop, service.settings
        # ---- the view (set by the receiver) ----
        self.scene: Scene | None = None
        self.camera: Camera | None = None
        self.camera_id: int | None = None
        self.width = self.height = 0
        self.quality = 80
        self.overrides: dict = {}  # painting settings the client changed from the scene's (a style among them)
        self.shown_time = 0.0  # the scene time of the last frame sent: what a pick sees
        self.params: PaintParams | None = None  # the scene's with the overrides, validated once when they change
        self.temporal = False  # per-frame paintings: every frame is the painting of its camera
        self.animate = False
        self.epoch = 0  # bumped by every hello: a painting of an older epoch shows another scene
        self.changed = asyncio.Event()
        # ---- the painting (kept by the painter) ----
        settings = self.settings
        self.planner = Planner(settings.frame_ms, settings.settle_ms, settings.max_work, _time.monotonic())
        self.painter = service.painter
        self.kept: int | None = None  # the last frame shown, whose per-pixel data the painter keeps (temporal)
        self.serial = 0  # frames asked for
        self.closed = False
        # ---- the outbox (drained by the sender) ----
        self.notes: collections.deque[str] = collections.deque(maxlen=64)  # text messages, in order
        self.frame: tuple[str, bytes] | None = None  # the newest frame not yet sent
        self.seq = 0
        self.dropped = 0
        self.outbox = asyncio.Event()

    # ---- the session's life ----

    async def run(self) -> None:
        try:
            async with asyncio.TaskGroup() as tasks:
                tasks.create_task(self._receive())
                tasks.create_task(self._paint())
                tasks.create_task(self._send())
                tasks.create_task(self._expect_hello())
        except* WebSocketDisconnect:
            pass
        finally:
            self.close()

    def close(self) -> None:
        """End the walk-through's painting: one still in flight stops at its next iteration."""
        self.closed = True
        self.painter.leave(self)

    @property
    def walking(self) -> bool:
        """Whether it has said hello: only then does it hold one of the server's ``max_sessions`` places."""
        return self.scene is not None

    async def _expect_hello(self) -> None:
        """Close a WebSocket that has not opened a walk-through within ``hello_timeout_s`` (1008): one that
        only holds a connection open is let go."""
        seconds = self.settings.hello_timeout_s
        await asyncio.sleep(seconds)
        if self.scene is None:
            message = f"no hello within {seconds:g} s"
            await self._deliver({"type": "websocket.send", "text": protocol.Error(message=message).model_dump_json()})
            await self.ws.close(code=1008, reason=message)
            raise WebSocketDisconnect(1008, message)

    async def _receive(self) -> None:
        while True:
            message = await self.ws.receive()
            if message["type"] == "websocket.disconnect":
                raise WebSocketDisconnect(message.get("code", 1000))
            text = message.get("text")
            limit = self.settings.max_message_bytes
            if text is None:
                self._note(protocol.Error(message="send JSON text messages; binary messages mean nothing here"))
            elif len(text) > limit:
                self._note(protocol.Error(message=f"a message of {len(text)} characters; the limit is {limit}"))
            else:
                await self._take(text)

    async def _take(self, text: str) -> None:
        try:
            msg = protocol.client_message.validate_json(text)
            if isinstance(msg, protocol.MoveMessage | protocol.PickMessage) and self.scene is not None:
                # milliseconds of rays in a big scene: off the event loop, the next message waits for the answer
                self._note(await asyncio.to_thread(self._answer, self.scene, self.camera or self.scene.camera, msg))
            else:
                self._apply(msg)
        except ValidationError as exc:
            self._note(protocol.Error(message=f"bad message: {one_line(exc)}"))
        except (CameraError, ValueError) as exc:
            self._note(protocol.Error(message=str(exc)))
        except Exception:  # a fault of ours: this message is lost, the session is not
            self._note(protocol.Error(message=fault_message(report_fault(f"session message {text[:200]!r}"))))

    def _apply(self, msg) -> None:
        if isinstance(msg, protocol.Hello):
            self._hello(msg)
        elif self.scene is None:
            raise ValueError(f"say hello first: a '{msg.type}' message needs a scene")
        elif isinstance(msg, protocol.CameraMessage):
            camera = camera_of(msg)
            # another projection or stereo layout is another painting: checked as the hello was (both eyes)
            self.params = check(self.settings, self.scene, camera, self.width, self.height, self.overrides).params
            kind = (camera.projection, camera.stereo)
            if self.camera is None or kind != (self.camera.projection, self.camera.stereo):
                self.kept = None  # another kind of picture: the recursion starts again
            self.camera = camera
            self.camera_id = msg.id
            self.planner.camera_moved(_time.monotonic())
        elif isinstance(msg, protocol.PaintMessage):
            overrides = {**self.overrides, **msg.changes()}
            overrides = {k: v for k, v in overrides.items() if v is not None}
            # refuse now, keep the old settings
            self.params = check(self.settings, self.scene, self.camera, self.width, self.height, overrides).params
            self.overrides = overrides
        elif isinstance(msg, protocol.ModeMessage):
            self.temporal = self.temporal if msg.temporal is None else msg.temporal
            self.animate = self.animate if msg.animate is None else msg.animate
        elif isinstance(msg, protocol.ViewMessage):
            width, height = msg.width or self.width, msg.height or self.height
            self.params = check(self.settings, self.scene, self.camera, width, height, self.overrides).params
            self.width, self.height, self.quality = width, height, msg.quality or self.quality
        self._changed()

    def _answer(
        self, scene: Scene, camera: Camera, msg: protocol.MoveMessage | protocol.PickMessage
    ) -> protocol.Moved | protocol.Picked:
        """Blocking: the answer to a question about the scene, which paints nothing: where a walker's move ends
        (the camera message that shows it follows), or what a pixel shows, with the object's outline."""
        if isinstance(msg, protocol.MoveMessage):
            step = walk(scene, self.shown_time, msg.eye, msg.delta, msg.height)
            x, y, z = (float(v) for v in step.eye)
            body = step.body
            return protocol.Moved(
                id=msg.id, eye=(x, y, z), radius=body.radius, height=body.height, standing=step.standing
            )
        size = camera.image_size(self.width, self.height)  # the painting the client shows: both eyes
        shown = pick(scene, self.shown_time, camera, *size, msg.x, msg.y)
        names = (None, None) if shown is None else shown
        mask = None if shown is None else pick_mask(scene, self.shown_time, camera, size, shown[0])
        return protocol.Picked(x=msg.x, y=msg.y, object=names[0], material=names[1], mask=mask)

    def _hello(self, msg: protocol.Hello) -> None:
        if self.scene is None and self.service.walking() >= self.settings.max_sessions:  # others said hello first
            raise ValueError(busy_message(self.settings.max_sessions))
        painting = asked(self.service, msg.scene, None, msg.width, msg.height, {})
        if self.scene is None:  # a place with the painter (on Ray, while it has room)
            try:
                self.painter.admit(self, painting.params, painting.scene)
            except Refusal as refusal:
                raise ValueError(refusal.message) from None
        self.params, self.scene = painting.params, painting.scene
        self.camera, self.camera_id = self.scene.camera, None
        self.width, self.height, self.quality = msg.width, msg.height, msg.quality
        self.overrides, self.kept = {}, None
        self.planner.scene_started(_time.monotonic())
        self.epoch += 1
        self.frame = None  # a frame of the scene being left must not follow the new `ready`
        self._note(
            protocol.Ready(
                scene=self.service.info(msg.scene),
                width=self.width,
                height=self.height,
                quality=self.quality,
                temporal=self.temporal,
                animate=self.animate,
            )
        )

    def _changed(self) -> None:
        self.planner.view_changed()
        self.changed.set()

    # ---- painting ----

    async def _paint(self) -> None:
        while True:
            job = self._next_job()
            if job is None:
                self.changed.clear()
                wait = self._until_rest()
                try:
                    await asyncio.wait_for(self.changed.wait(), wait)
                except TimeoutError:
                    pass
                continue
            try:
                painted = await self.workshop.run(partial(self.painter.walk_frame, self, job.frame, self._stop(job)))
            except Abandoned:
                if self.workshop.stopping:
                    return  # the server is stopping: nothing will paint again
                continue
            except Exception as exc:  # this view cannot be painted: say why, and wait for the next change
                self.planner.frame_failed(job.plan, self._view())
                if isinstance(exc, (CameraError, ValueError)):  # e.g. a painting setting the scene cannot take
                    self._note(protocol.Error(message=str(exc)))
                else:
                    self._note(protocol.Error(message=fault_message(report_fault(f"painting {job.plan.phase} frame"))))
                continue
            if job.epoch != self.epoch:
                continue  # painted for a scene the client has left
            self._finished(job, painted)

    def _view(self) -> View:
        # hello sets the scene and its settings together
        assert self.scene is not None and self.params is not None, "a view is asked for only after hello"
        moving = self.animate and self.scene.animated
        camera = self.camera or self.scene.camera
        eyes = 1 if camera.stereo == "mono" else 2
        return View(self.width, self.height, self.params, self.temporal, moving, eyes)

    def _until_rest(self) -> float | None:
        """Seconds until refinement starts, None when nothing is due (the planner's, once there is a scene)."""
        return None if self.scene is None else self.planner.until_rest(_time.monotonic(), self._view())

    def _next_job(self) -> Job | None:
        if self.scene is None:
            return None
        plan = self.planner.next_frame(_time.monotonic(), self._view())
        if plan is None:
            return None
        assert self.camera is not None, "hello sets the camera with the scene"
        size = self.camera.image_size(plan.width, plan.height)
        after = self.kept if plan.continues else None
        self.serial += 1
        quality = frame_quality(plan, self.quality)
        frame = WalkFrame(self.scene, self.camera, *size, plan.params, plan.time, quality, self.serial, after)
        return Job(plan, self.epoch, self.camera_id, frame)

    def _stop(self, job: Job) -> Callable[[], bool]:
        """Refinements are abandoned as soon as anything changes; walk frames are short by design and always
        finish, or a camera that never rests would never see a frame."""
        plan = job.plan

        def should_stop() -> bool:
            stale = self.planner.version != plan.version if plan.phase == "refine" else self.epoch != job.epoch
            return self.closed or stale

        return should_stop

    def _finished(self, job: Job, frame: WalkPainted) -> None:
        plan = job.plan
        self.planner.frame_painted(plan, frame.seconds)
        self.kept = frame.serial
        self.shown_time = plan.time
        meta = protocol.Frame(
            seq=0,
            width=frame.width,
            height=frame.height,
            render_ms=round(frame.seconds * 1000, 2),
            iteration=plan.iteration,
            spp=plan.params.spp,
            scale=round(plan.width / self.width, 4),
            phase=plan.phase,
            final=plan.final,
            temporal=frame.continued,
            quality=job.frame.quality,
            paint=plan.params.settings(),
            camera_id=job.camera_id,
            time=plan.time,
            dropped=0,
        )
        self._post_frame(meta, frame.jpeg)

    # ---- sending ----

    def _note(self, message) -> None:
        self.notes.append(message.model_dump_json())
        self.outbox.set()

    def _post_frame(self, meta: protocol.Frame, jpeg: bytes) -> None:
        if self.frame is not None:
            self.dropped += 1  # never sent: this newer frame replaces it
        self.seq += 1
        self.frame = (meta.model_copy(update={"seq": self.seq, "dropped": self.dropped}).model_dump_json(), jpeg)
        self.outbox.set()

    async def _send(self) -> None:
        while True:
            await self.outbox.wait()
            self.outbox.clear()
            while self.notes:
                await self._deliver({"type": "websocket.send", "text": self.notes.popleft()})
            if self.frame is not None:
                text, jpeg = self.frame
                self.frame = None
                await self._deliver({"type": "websocket.send", "text": text})
                await self._deliver({"type": "websocket.send", "bytes": jpeg})

    async def _deliver(self, message: dict) -> None:
        """A send waits while the client's buffers are full (newer frames replace the unsent one meanwhile);
        a client that takes nothing for ``send_timeout_s`` has gone and is let go."""
        try:
            await asyncio.wait_for(self.ws.send(message), self.settings.send_timeout_s)
        except TimeoutError:
            raise WebSocketDisconnect(1001, "the client took no data") from None
