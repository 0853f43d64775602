"""What a walk-through shows, and how each message changes it: a pure reducer, ``apply(view, message) -> view |
refusal``, with no socket, no painter and no clock (the session does the I/O around it).

A message the view cannot take is refused whole (the view stays as it was) with the same line every door
gives for the same request (``asked.py``). ``move`` and ``pick`` are questions about the scene, not changes of
the view: the session answers them (:func:`answer`).
"""

from __future__ import annotations

import base64
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..camera.camera import Camera
from ..camera.wire import camera_of
from ..media.walkframe import WalkFrame, WalkPainted
from ..painting.picking import object_pixels, pick
from ..painting.sequence import frame_params
from ..scene.scene import Scene
from ..scene.walking import walk
from ..settings.params import PaintParams
from . import protocol
from .asked import check
from .planner import Plan, View, frame_quality
from .refusal import Refusal
from .settings import Settings

MASK_PIXELS = 160 * 90 * 4  # a picked object's outline is traced at most this fine (a few ms of rays)


@dataclass(frozen=True)
class WalkView:
    """The view: the scene (None before hello) and its camera (``camera_id``: the client's id of it), the
    canvas (one eye's ``width x height``) and its JPEG quality, the client's changes of the scene's painting
    settings (``overrides``) and the settings they make (``params``), the modes, and ``epoch``, bumped by every
    hello (a painting of an older epoch shows another scene)."""

    scene: Scene | None = None
    camera: Camera | None = None
    camera_id: int | None = None
    width: int = 0
    height: int = 0
    quality: int = 80
    overrides: dict[str, Any] = field(default_factory=dict)
    params: PaintParams | None = None
    temporal: bool = False
    animate: bool = False
    epoch: int = 0

    def planned(self) -> View:
        """The view as the planner sees it (after hello)."""
        assert self.scene is not None and self.params is not None and self.camera is not None, "after hello"
        eyes = 1 if self.camera.stereo == "mono" else 2
        moving = self.animate and self.scene.animated
        return View(self.width, self.height, self.params, self.temporal, moving, eyes)


ViewMessage = (
    protocol.Hello | protocol.CameraMessage | protocol.PaintMessage | protocol.ModeMessage | protocol.ViewMessage
)


def apply(
    view: WalkView, message: ViewMessage, settings: Settings, find_scene: Callable[[str], Scene]
) -> WalkView | Refusal:
    """The view after ``message``, or the :class:`Refusal` that leaves it as it was. ``find_scene``: the scene a
    name stands for, or :class:`Refusal` 404."""
    try:
        if isinstance(message, protocol.Hello):
            scene = find_scene(message.scene)
            params = check(settings, scene, None, message.width, message.height, {}).params
            return replace(
                view, scene=scene, camera=scene.camera, camera_id=None, overrides={}, params=params,
                epoch=view.epoch + 1, width=message.width, height=message.height, quality=message.quality,
            )  # fmt: skip
        if view.scene is None:
            raise Refusal(f"say hello first: a '{message.type}' message needs a scene")
        if isinstance(message, protocol.CameraMessage):
            try:
                camera = camera_of(message)
            except ValueError as exc:  # CameraError among them
                raise Refusal(str(exc)) from None
            # another projection or stereo layout is another painting: checked as the hello was (both eyes)
            params = check(settings, view.scene, camera, view.width, view.height, view.overrides).params
            return replace(view, camera=camera, camera_id=message.id, params=params)
        if isinstance(message, protocol.PaintMessage):
            overrides = {**view.overrides, **message.changes()}
            overrides = {k: v for k, v in overrides.items() if v is not None}
            params = check(settings, view.scene, view.camera, view.width, view.height, overrides).params
            return replace(view, overrides=overrides, params=params)
        if isinstance(message, protocol.ModeMessage):
            temporal = view.temporal if message.temporal is None else message.temporal
            animate = view.animate if message.animate is None else message.animate
            return replace(view, temporal=temporal, animate=animate)
        width, height = message.width or view.width, message.height or view.height
        params = check(settings, view.scene, view.camera, width, height, view.overrides).params
        return replace(view, width=width, height=height, quality=message.quality or view.quality, params=params)
    except Refusal as refusal:
        return refusal


def another_picture(before: WalkView, after: WalkView) -> bool:
    """Whether ``after`` paints another kind of picture than ``before`` (another scene, projection or stereo
    layout): the recursion starts again from ``I_0``."""
    if before.epoch != after.epoch or before.camera is None or after.camera is None:
        return True
    return (before.camera.projection, before.camera.stereo) != (after.camera.projection, after.camera.stereo)


def pick_mask(scene: Scene, time: float, camera: Camera, size: tuple[int, int], name: str) -> protocol.PickMask:
    """Where object ``name`` shows in a view of ``size`` (width, height), at most ``MASK_PIXELS`` fine."""
    scale = min(1.0, math.sqrt(MASK_PIXELS / (size[0] * size[1])))
    width, height = max(1, round(size[0] * scale)), max(1, round(size[1] * scale))
    shows = object_pixels(scene, time, camera, width, height, name)
    bits = base64.b64encode(np.packbits(shows.reshape(-1)).tobytes()).decode()
    return protocol.PickMask(width=width, height=height, bits=bits)


def answer(
    view: WalkView, time: float, message: protocol.MoveMessage | protocol.PickMessage
) -> protocol.Moved | protocol.Picked:
    """Blocking: the answer to a question about the scene of ``view`` at scene ``time``, which paints nothing:
    where a walker's move ends (the camera message that shows it follows), or what a pixel shows, with the
    object's outline."""
    scene, camera = view.scene, view.camera
    assert scene is not None and camera is not None, "questions are answered after hello"
    if isinstance(message, protocol.MoveMessage):
        step = walk(scene, time, message.eye, message.delta, message.height)
        x, y, z = (float(v) for v in step.eye)
        body = step.body
        return protocol.Moved(
            id=message.id, eye=(x, y, z), radius=body.radius, height=body.height, standing=step.standing
        )
    size = camera.image_size(view.width, view.height)  # the painting the client shows: both eyes
    shown = pick(scene, time, camera, *size, message.x, message.y)
    names = (None, None) if shown is None else shown
    mask = None if shown is None else pick_mask(scene, time, camera, size, shown[0])
    return protocol.Picked(x=message.x, y=message.y, object=names[0], material=names[1], mask=mask)


@dataclass(frozen=True)
class Job:
    """One frame to paint: the planner's plan, the frame as the painter takes it, and the view it shows."""

    plan: Plan
    epoch: int
    camera_id: int | None
    frame: WalkFrame

    def meta(self, painted: WalkPainted, canvas_width: int) -> protocol.Frame:
        """The ``frame`` message that goes before the painted frame's JPEG (``seq`` and ``dropped`` are the
        outbox's)."""
        plan = self.plan
        return protocol.Frame(
            seq=0, width=painted.width, height=painted.height, render_ms=round(painted.seconds * 1000, 2),
            iteration=plan.iteration, spp=plan.params.spp, scale=round(plan.width / canvas_width, 4),
            phase=plan.phase, final=plan.final, temporal=painted.continued, quality=self.frame.quality,
            paint=self.frame.params.settings(), camera_id=self.camera_id, time=plan.time, dropped=0,
            projection=self.frame.camera.projection, stereo=self.frame.camera.stereo,
            bands=[(y, rows) for y, rows, _ in painted.bands] or None,
        )  # fmt: skip


def job_of(view: WalkView, plan: Plan, serial: int, kept: int | None, walked: int) -> Job:
    """Frame ``serial`` of ``view`` as ``plan`` paints it, going on from frame ``kept`` when the plan continues.

    A walk frame is frame ``walked`` of a film (the walk frames before it) for ``boil``: with ``boil = k`` its
    noise and jitter are reseeded every ``k`` walk frames, by the films' own rule (``sequence.frame_params``). A
    refinement is the still of its view, as a REST render and Save paint it: the painting at rest does not
    boil."""
    assert view.scene is not None and view.camera is not None, "painted after hello"
    size = view.camera.image_size(plan.width, plan.height)
    after = kept if plan.continues else None
    quality = frame_quality(plan, view.quality)
    params = frame_params(plan.params, None, walked) if plan.phase == "walk" else plan.params
    frame = WalkFrame(view.scene, view.camera, *size, params, plan.time, quality, serial, after)
    return Job(plan, view.epoch, view.camera_id, frame)
