"""What a walk-through paints next: walk frames while the camera moves, refinements once it rests.

Pure arithmetic on clocks and counters: no I/O, no painting. The session tells the :class:`Planner` what
happened (the view changed, the camera moved, a frame was painted in so many seconds) and asks it for the
next frame's :class:`Plan`, or how long to wait for one. Clocks are monotonic seconds, passed in as ``now``.

While the camera moves, *walk* frames hold the frame budget: one sample per pixel, at the largest of
:data:`SCALES` that the measured seconds per ray allow, each the painting of its camera (all iterations
from the canvas) at that size, its smudges as long in the picture as the canvas's (``PaintParams.at_scale``);
in temporal mode, asked for explicitly, one iteration continuing from the last frame instead (the paper's
``I_n = F(I_{n-1}, S(n))``). Once the camera has been still for ``settle_ms``, *refine* frames paint the
full canvas with all iterations: first at the painting's own samples, then at :data:`REFINE_SPP` or more
(what the work limit allows), the final one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

from ..settings.params import PaintParams

SCALES = (1.0, 0.875, 0.75, 0.625, 0.5, 0.375, 0.25)  # walk-frame sizes, as fractions of the canvas
FIRST_SCALE = 0.5  # the walk-frame size before any painting has been timed
REFINE_SPP = 4  # once at rest, the second refinement takes at least this many samples per pixel
MAX_REFINE_SPP = 64  # ... and at most this many: past it the image no longer visibly changes
REFINE_TIMES = 2  # ... and between the two, this many times the painting's own (protocol.RefineRule tells clients)
WALK_SHARE = 0.8  # of the frame budget, for painting a walk frame; encoding and sending take the rest
WALK_QUALITY = 70  # the most JPEG quality a walk frame is sent with: fewer bytes while the eye is moving
SOON = 0.005  # seconds: the shortest wait for rest, so a wait that is due still yields to the receiver


@dataclass(frozen=True)
class View:
    """What the walk-through shows, as far as the policy cares.

    width, height : the canvas in pixels (one eye's image); params : the scene's painting settings with the
    client's changes; temporal : walk frames continue the last frame; moving : the scene is animated and the
    client animates it, so it never rests; eyes : the images a painting holds (2 for a stereo camera: both are
    painted, and both count in the work)."""

    width: int
    height: int
    params: PaintParams
    temporal: bool
    moving: bool
    eyes: int = 1


@dataclass(frozen=True)
class Plan:
    """One frame to paint: ``width`` x ``height`` pixels per eye (``eyes`` of them) with ``params``, at scene
    ``time`` (seconds).

    continues : start from the last frame's state (resized to this size), not from the canvas;
    iteration : the recursion's iterations behind this frame once painted; final : the last refinement
    (nothing more is painted until the view changes); version : the view it shows."""

    phase: Literal["walk", "refine"]
    width: int
    height: int
    params: PaintParams
    continues: bool
    iteration: int
    final: bool
    time: float
    version: int
    eyes: int = 1


@dataclass
class Planner:
    """The walk/refine policy of one walk-through, with the clocks and counters it reads.

    frame_ms : aim for walk frames at least this fast; settle_ms : the camera rests after this long without
    moving; max_work : pixels x samples x iterations one painting may take; started : when the walk-through
    began (the scene's clock starts there)."""

    frame_ms: float
    settle_ms: float
    max_work: int
    started: float
    version: int = 0  # bumped by every change of the view; a painting of an older version is stale
    painted_version: int = -1  # the version last painted (or found unpaintable)
    refinements: int = 0  # refinement frames painted of that version
    iteration: int = 0  # the iterations behind the last frame's state; 0: none, start from the canvas
    seconds_per_ray: float | None = None  # measured cost of one ray-iteration, for walk frames
    last_move: float = 0.0  # when the camera last moved

    # ---- what happened ----

    def view_changed(self) -> None:
        self.version += 1

    def camera_moved(self, now: float) -> None:
        self.last_move = now

    def scene_started(self, now: float) -> None:
        """A new scene (a ``hello``): nothing painted yet, the camera just placed."""
        self.iteration = 0
        self.last_move = now

    def frame_painted(self, plan: Plan, seconds: float) -> None:
        """``plan`` was painted in ``seconds`` (and sent): time it, and count it."""
        params = plan.params
        measured = seconds / (plan.width * plan.height * plan.eyes * params.spp * params.iterations)
        previous = self.seconds_per_ray  # a running mean: one slow frame does not halve the next one's size
        self.seconds_per_ray = measured if previous is None else 0.7 * previous + 0.3 * measured
        self.iteration = plan.iteration
        self.refinements = self.refinements + 1 if plan.phase == "refine" and plan.version == self.version else 0
        self.painted_version = plan.version

    def frame_failed(self, plan: Plan, view: View) -> None:
        """``plan`` cannot be painted: paint nothing more of its version."""
        self.painted_version, self.refinements = plan.version, len(self.refine_spp(view))

    # ---- what comes next ----

    def next_frame(self, now: float, view: View) -> Plan | None:
        """The frame to paint now, or None: nothing is due (see :meth:`until_rest`)."""
        scene_time = now - self.started if view.moving else 0.0
        if self.painted_version != self.version or view.moving:
            return self._walk(view, scene_time)
        if self.rest_in(now) > 0 or not self._refinements_left(view):
            return None
        steps = self.refine_spp(view)
        params = replace(view.params, spp=steps[self.refinements])
        final = self.refinements == len(steps) - 1
        return self._plan("refine", view, view.width, view.height, params, False, scene_time, final)

    def until_rest(self, now: float, view: View) -> float | None:
        """Seconds until the camera counts as resting and refinement starts; None when nothing is due."""
        if self.painted_version != self.version:
            return None
        return max(self.rest_in(now), SOON) if self._refinements_left(view) else None

    def rest_in(self, now: float) -> float:
        """Seconds until the camera has been still for ``settle_ms`` (0 or less: it rests)."""
        return self.last_move + self.settle_ms / 1000 - now

    def refine_spp(self, view: View) -> list[int]:
        """The samples per pixel of each refinement: the painting's own, then more if the work limit allows
        (the pixels of both eyes of a stereo pair count)."""
        params = view.params
        affordable = self.max_work // (view.width * view.height * view.eyes * params.iterations)
        more = max(params.spp, min(MAX_REFINE_SPP, max(REFINE_SPP, REFINE_TIMES * params.spp), affordable))
        return [params.spp] if more == params.spp else [params.spp, more]

    def walk_scale(self, view: View) -> float:
        """The largest walk-frame size whose painting fits the frame budget at the measured speed."""
        if self.seconds_per_ray is None:
            return FIRST_SCALE
        iterations = 1 if self._continues(view) else view.params.iterations
        budget = WALK_SHARE * self.frame_ms / 1000
        affordable = budget / (self.seconds_per_ray * iterations * view.width * view.height * view.eyes)
        return next((s for s in SCALES if s * s <= affordable), SCALES[-1])

    # ---- inside ----

    def _refinements_left(self, view: View) -> bool:
        return self.refinements < len(self.refine_spp(view))

    def _continues(self, view: View) -> bool:
        return view.temporal and self.iteration > 0

    def _walk(self, view: View, scene_time: float) -> Plan:
        scale = self.walk_scale(view)
        width, height = max(1, round(view.width * scale)), max(1, round(view.height * scale))
        if view.width % view.height == 0:  # a whole aspect stays whole: a panorama stays twice as wide as high
            width = height * (view.width // view.height)
        continues = self._continues(view)
        params = replace(view.params, iterations=1, spp=1) if continues else replace(view.params, spp=1)
        params = params.at_scale(height / view.height)  # lambda_p counts pixels: a pixel's pitch goes with the height
        return self._plan("walk", view, width, height, params, continues, scene_time, False)

    def _plan(
        self, phase, view: View, width, height, params: PaintParams, continues: bool, scene_time: float, final
    ) -> Plan:
        iteration = self.iteration + params.iterations if continues else params.iterations
        return Plan(phase, width, height, params, continues, iteration, final, scene_time, self.version, view.eyes)


def frame_quality(plan: Plan, quality: int) -> int:
    """The JPEG quality of ``plan``'s frame for a client that asked for ``quality``: lower while walking,
    as remote viewers do (a moving picture hides it; the painting at rest gets the quality asked for)."""
    return min(quality, WALK_QUALITY) if plan.phase == "walk" else quality
