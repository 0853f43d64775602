"""A walk's frames as jobs: the planner's next frame numbered (a walk frame also counted, as a film's frames are
for ``boil``), and what the last one shown leaves behind."""

from __future__ import annotations

from ..media.walkframe import WalkPainted
from . import protocol
from .planner import Planner
from .walkview import Job, WalkView, job_of


class WalkJobs:
    """The frames one walk asks for and shows: each numbered as the planner asks for it, the frame whose per-pixel
    data the painter keeps (temporal), and the scene time last shown (what a pick sees)."""

    def __init__(self, planner: Planner):
        self.planner = planner
        self.kept: int | None = None  # the last frame shown, whose per-pixel data the painter keeps (temporal)
        self.shown_time = 0.0  # the scene time of the last frame sent: what a pick sees
        self.serial = 0  # frames asked for
        self.walked = 0  # walk frames asked for: what ``boil`` counts

    def next(self, view: WalkView, now: float) -> Job | None:
        """The frame to paint next for ``view`` at ``now`` (monotonic seconds), or None: nothing to paint."""
        if view.scene is None or view.camera is None:
            return None
        plan = self.planner.next_frame(now, view.planned())
        if plan is None:
            return None
        self.serial += 1
        job = job_of(view, plan, self.serial, self.kept, self.walked)
        self.walked += plan.phase == "walk"
        return job

    def finished(self, job: Job, frame: WalkPainted, width: int) -> tuple[protocol.Frame, list[bytes]]:
        """``frame`` painted for ``job`` is shown: the planner learns its time; its meta and its JPEGs to post."""
        plan = job.plan
        self.planner.frame_painted(plan, frame.seconds)
        self.kept, self.shown_time = frame.serial, plan.time
        return job.meta(frame, width), [jpeg for _, _, jpeg in frame.bands] or [frame.jpeg]
