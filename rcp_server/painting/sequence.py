"""Painting a sequence of frames, in order, per frame or temporally; whoever paints a frame is given.

A sequence is a list of shots (a camera and a scene time each): a camera path's frames
(``camerapath.PathFrame``) or ``rcp render --frames``' orbit and walk. Per-frame mode paints every frame from
``I_0`` with all of ``params.iterations``; a shot that carries ``looks`` (a path that keys its painting,
``keyedpaint.py``) paints with those in place of ``params``, and blends two within a cross-fade; temporal
mode (``temporal=K``) paints the first frame so, then each later one with ``K`` iterations from the previous
frame's painting (the paper's ``I_n = F(I_{n-1}, S(n))``).
That rule lives here only: the threads of one machine (:func:`paint_sequence`), the service's shared pool and
Ray's actors (``cluster.py``) all follow it.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from ..camera.camera import Camera
from ..engine.paintstate import PaintState
from ..settings.params import PaintParams

Looks = tuple[tuple[PaintParams, float], ...]
"""A frame's paintings and their weights (summing to 1): one at weight 1, or two blended within a fade."""


class Shot(Protocol):
    """A frame to paint: what the camera sees at what scene time (``camerapath.PathFrame`` is one)."""

    @property
    def camera(self) -> Camera: ...

    @property
    def scene_time(self) -> float: ...


class FramePainter(Protocol):
    """Paints one frame: ``(camera, scene_time, params, previous) -> PaintResult`` (``painting.paint`` with the
    scene, the size and where the tiles run already bound)."""

    def __call__(self, camera: Camera, scene_time: float, params: PaintParams, previous: PaintState | None, /): ...


def frame_params(params: PaintParams, temporal: int | None, index: int) -> PaintParams:
    """The settings of frame ``index``: all iterations from ``I_0``, or ``temporal`` from the previous frame;
    with ``boil = k``, the seed moved on by one every ``k`` frames (the noise and the jitter boil)."""
    if params.boil:
        params = replace(params, seed=(params.seed + index // params.boil) % 2**31)
    return params if not temporal or index == 0 else replace(params, iterations=temporal)


def paint_sequence(
    paint_frame: FramePainter, shots: Iterable[Shot], params: PaintParams, temporal: int | None = None
) -> Iterator[np.ndarray]:
    """The paintings of ``shots`` in order, each (h, w, 3) float32, painted one after another."""
    for result in paint_results(paint_frame, shots, params, temporal):
        yield result.image


def paint_results(
    paint_frame: FramePainter,
    shots: Iterable[Shot],
    params: PaintParams,
    temporal: int | None = None,
    first: int = 0,
    previous: PaintState | None = None,
) -> Iterator:
    """:func:`paint_sequence`'s paintings as the painter's results (image and state), from frame ``first`` of
    the sequence on (``shots`` start there); temporal from ``first > 0``, ``previous`` is frame ``first - 1``'s
    state (a job that resumes after a restart)."""
    if temporal and first > 0 and previous is None:
        raise ValueError("a temporal sequence resumed past its first frame needs the previous frame's state")
    for index, shot in enumerate(shots, first):
        result = paint_looks(
            paint_frame, shot.camera, shot.scene_time, frame_looks(shot, params, temporal, index), previous
        )
        previous = result.state if temporal else None
        yield result


def frame_looks(shot: Shot, params: PaintParams, temporal: int | None, index: int) -> Looks:
    """The paintings of frame ``index`` and their weights: the shot's own ``looks`` (a path that keys its
    painting), else ``params``; each with :func:`frame_params`' iterations and seed."""
    looks = getattr(shot, "looks", ()) or ((params, 1.0),)
    return tuple((frame_params(look, temporal, index), weight) for look, weight in looks)


def paint_looks(
    paint_frame: FramePainter, camera: Camera, scene_time: float, looks: Looks, previous: PaintState | None
):
    """One frame painted with each of its ``looks`` from ``previous``: the painter's result, or the :class:`Blend`
    of two within a cross-fade. Ray's actors paint a frame (or a band of its rows) with it too."""
    results = [(paint_frame(camera, scene_time, look, previous), weight) for look, weight in looks]
    return results[0][0] if len(results) == 1 else Blend.of(results)


@dataclass(frozen=True)
class Blend:
    """A frame that is the blend of two paintings (a cross-fade of a keyed painting): ``image`` the weighted
    sum of theirs; ``state`` the heavier one's, which a temporal film goes on from."""

    image: np.ndarray
    state: PaintState
    stage_seconds: dict[str, float]

    @classmethod
    def of(cls, results: list[tuple[Any, float]]) -> Blend:
        image = sum((np.float32(w) * r.image for r, w in results), np.zeros_like(results[0][0].image))
        heavier = max(results, key=lambda rw: rw[1])[0]
        seconds: dict[str, float] = {}
        for r, _ in results:
            for stage, s in r.stage_seconds.items():
                seconds[stage] = seconds.get(stage, 0.0) + s
        return cls(image.astype(np.float32), heavier.state, seconds)
