"""One WebSocket walk-through: camera in, painted frames out, the newest camera always wins.

Three tasks share a session. The receiver validates messages and updates the view; every change bumps
``version``, which abandons a painting in flight between iterations. The painter renders the newest view:
while the camera moves, *walk* frames (temporal mode: one iteration continuing from the last frame, the
paper's ``I_n = F(I_{n-1}, S(n))``; resolution chosen from the measured speed to hold the frame rate);
once it rests, *refine* frames at full resolution with all iterations and then more samples. The sender
keeps one slot for frames: a frame not yet sent is replaced by a newer one, so a slow client never
gets a queue of stale frames.
"""

from __future__ import annotations

import asyncio
import collections
import time as _time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from fastapi import WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from .. import images
from ..camera import Camera, CameraError
from ..painting import Abandoned, PaintResult, PaintState
from ..params import PaintParams
from ..scene import Scene
from ..scenefile import one_line
from . import protocol
from .faults import fault_message, report_fault

if TYPE_CHECKING:
    from .app import Service

SCALES = (1.0, 0.875, 0.75, 0.625, 0.5, 0.375, 0.25)  # walk-frame sizes, as fractions of the canvas
REFINE_SPP = 4  # once at rest, the second refinement takes at least this many samples per pixel


@dataclass
class _Job:
    """One frame to paint: a snapshot of the view it shows, and how to paint it."""

    version: int
    epoch: int
    scene: Scene
    camera: Camera
    camera_id: int | None
    phase: str
    width: int
    height: int
    params: PaintParams
    previous: PaintState | None
    time: float
    iteration: int
    final: bool
    quality: int


class Session:
    def __init__(self, ws: WebSocket, service: Service):
        self.ws, self.service, self.renderer, self.settings = ws, service, service.renderer, service.settings
        # ---- the view (set by the receiver) ----
        self.scene: Scene | None = None
        self.camera: Camera | None = None
        self.camera_id: int | None = None
        self.width = self.height = 0
        self.quality = 80
        self.overrides: dict = {}  # painting settings the client changed from the scene's
        self.temporal = True
        self.animate = False
        self.version = 0  # bumped by every change; a painting of an older version is stale
        self.epoch = 0  # bumped by every hello: a painting of an older epoch shows another scene
        self.last_move = 0.0  # when the camera last moved (monotonic seconds)
        self.changed = asyncio.Event()
        # ---- the painting (kept by the painter) ----
        self.state: PaintState | None = None  # the last frame's per-pixel data, for temporal mode
        self.iteration = 0
        self.painted_version = -1
        self.refinements = 0  # refinement frames sent for the painted version
        self.seconds_per_ray: float | None = None  # measured cost of one ray-iteration, for walk frames
        self.clock0 = _time.monotonic()
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
        except* WebSocketDisconnect:
            pass
        finally:
            self.closed = True  # a painting still in flight stops at its next iteration

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
                self._take(text)

    def _take(self, text: str) -> None:
        try:
            self._apply(protocol.client_message.validate_json(text))
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
            self.camera = Camera(msg.eye, msg.look_at, msg.up, msg.fov)
            self.camera_id = msg.id
            self.last_move = _time.monotonic()
        elif isinstance(msg, protocol.PaintMessage):
            overrides = {**self.overrides, **msg.changes()}
            overrides = {k: v for k, v in overrides.items() if v is not None}
            self._check(self.scene, self.width, self.height, overrides)  # refuse now, keep the old settings
            self.overrides = overrides
        elif isinstance(msg, protocol.ModeMessage):
            self.temporal = self.temporal if msg.temporal is None else msg.temporal
            self.animate = self.animate if msg.animate is None else msg.animate
        elif isinstance(msg, protocol.ViewMessage):
            width, height = msg.width or self.width, msg.height or self.height
            self._check(self.scene, width, height, self.overrides)
            self.width, self.height, self.quality = width, height, msg.quality or self.quality
        self._changed()

    def _hello(self, msg: protocol.Hello) -> None:
        scenes = self.service.scenes
        if msg.scene not in scenes:
            raise ValueError(f"unknown scene {msg.scene!r}; known: {', '.join(sorted(scenes))}")
        self._check(scenes[msg.scene], msg.width, msg.height, {})
        self.scene = scenes[msg.scene]
        self.camera, self.camera_id = self.scene.camera, None
        self.width, self.height, self.quality = msg.width, msg.height, msg.quality
        self.overrides, self.state, self.iteration = {}, None, 0
        self.epoch += 1
        self.frame = None  # a frame of the scene being left must not follow the new `ready`
        self.last_move = _time.monotonic()
        self._note(
            protocol.Ready(
                scene=self.service.infos[msg.scene],
                width=self.width,
                height=self.height,
                quality=self.quality,
                temporal=self.temporal,
                animate=self.animate,
            )
        )

    def _check(self, scene: Scene, width: int, height: int, overrides: dict) -> None:
        """Refuses a view whose paintings could not be made: a bad setting, or more work than one may take."""
        self.settings.check_painting(width, height, replace(scene.paint, **overrides))

    def _changed(self) -> None:
        self.version += 1
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
                result, seconds = await self.renderer.run(lambda job=job: self._render(job))
            except Abandoned:
                if self.renderer.stopping:
                    return  # the server is stopping: nothing will paint again
                continue
            except Exception as exc:  # this view cannot be painted: say why, and wait for the next change
                self.painted_version, self.refinements = job.version, len(self._refine_spp())
                if isinstance(exc, (CameraError, ValueError)):  # e.g. a painting setting the scene cannot take
                    self._note(protocol.Error(message=str(exc)))
                else:
                    self._note(protocol.Error(message=fault_message(report_fault(f"painting {job.phase} frame"))))
                continue
            if job.epoch != self.epoch:
                continue  # painted for a scene the client has left
            self._finished(job, result, seconds)

    def _until_rest(self) -> float | None:
        """Seconds until the camera counts as resting (then refinement starts), None when nothing is due."""
        if self.scene is None or self.painted_version != self.version:
            return None
        return max(self._rest_in(), 0.005) if self._refinements_left() else None

    def _rest_in(self) -> float:
        """Seconds until the camera has been still for ``settle_ms`` (0 or less: it rests)."""
        return self.last_move + self.settings.settle_ms / 1000 - _time.monotonic()

    def _refinements_left(self) -> bool:
        return self.refinements < len(self._refine_spp())

    def _refine_spp(self) -> list[int]:
        params = self._params()
        affordable = self.settings.max_work // (self.width * self.height * params.iterations)
        more = max(params.spp, min(64, max(REFINE_SPP, 2 * params.spp), affordable))
        return [params.spp] if more == params.spp else [params.spp, more]

    def _params(self) -> PaintParams:
        return replace(self.scene.paint, **self.overrides)

    def _next_job(self) -> _Job | None:
        if self.scene is None:
            return None
        params = self._params()
        now = _time.monotonic()
        scene_time = now - self.clock0 if self.animate and self.scene.animated else 0.0
        walking = self.painted_version != self.version or (self.animate and self.scene.animated)
        if walking:
            return self._walk_job(params, scene_time)
        if self._rest_in() > 0 or not self._refinements_left():
            return None
        spp = self._refine_spp()[self.refinements]
        final = self.refinements == len(self._refine_spp()) - 1
        return self._job("refine", self.width, self.height, replace(params, spp=spp), None, scene_time, final)

    def _walk_job(self, params: PaintParams, scene_time: float) -> _Job:
        scale = self._walk_scale(params)
        width, height = max(1, round(self.width * scale)), max(1, round(self.height * scale))
        previous = None
        if self.temporal and self.state is not None:
            previous = self.state.resized(width, height)
            params = replace(params, iterations=1, spp=1)
        else:
            params = replace(params, spp=1)
        return self._job("walk", width, height, params, previous, scene_time, False)

    def _job(self, phase, width, height, params, previous, scene_time, final) -> _Job:
        iteration = self.iteration + params.iterations if previous is not None else params.iterations
        return _Job(
            self.version,
            self.epoch,
            self.scene,
            self.camera,
            self.camera_id,
            phase,
            width,
            height,
            params,
            previous,
            scene_time,
            iteration,
            final,
            self.quality,
        )

    def _walk_scale(self, params: PaintParams) -> float:
        """The largest walk-frame size whose painting fits the frame budget at the measured speed."""
        if self.seconds_per_ray is None:
            return 0.5
        iterations = 1 if self.temporal and self.state is not None else params.iterations
        budget = 0.8 * self.settings.frame_ms / 1000
        affordable = budget / (self.seconds_per_ray * iterations * self.width * self.height)
        return next((s for s in SCALES if s * s <= affordable), SCALES[-1])

    def _render(self, job: _Job) -> tuple[tuple[PaintResult, bytes], float]:
        """Blocking, on a render thread: paint the job and encode it. Refinements are abandoned as soon as
        anything changes; walk frames are short by design and always finish, or a camera that never rests
        would never see a frame."""

        def should_stop() -> bool:
            stale = self.version != job.version if job.phase == "refine" else self.epoch != job.epoch
            return self.closed or stale

        clock = _time.perf_counter()
        result = self.renderer.paint(
            job.scene,
            job.camera,
            job.width,
            job.height,
            job.params,
            time=job.time,
            previous=job.previous,
            should_stop=should_stop,
        )
        seconds = _time.perf_counter() - clock
        return (result, images.encode(result.image, "JPEG", job.quality)), seconds

    def _finished(self, job: _Job, painted: tuple[PaintResult, bytes], seconds: float) -> None:
        result, jpeg = painted
        measured = seconds / (job.width * job.height * job.params.spp * job.params.iterations)
        self.seconds_per_ray = measured if self.seconds_per_ray is None else 0.7 * self.seconds_per_ray + 0.3 * measured
        self.state, self.iteration = result.state, job.iteration
        self.refinements = self.refinements + 1 if job.phase == "refine" and job.version == self.version else 0
        self.painted_version = job.version
        meta = protocol.Frame(
            seq=0,
            width=job.width,
            height=job.height,
            render_ms=round(seconds * 1000, 2),
            iteration=job.iteration,
            spp=job.params.spp,
            scale=round(job.width / self.width, 4),
            phase=job.phase,
            final=job.final,
            temporal=job.previous is not None,
            camera_id=job.camera_id,
            time=job.time,
            dropped=0,
        )
        self._post_frame(meta, jpeg)

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
