"""The painting keyed along a camera path: the settings of every frame, from the keyframes that give them.

A keyframe's ``"paint"`` is a table of painting settings in the form of a ``--paint`` file or a REST body
(``style``, settings by name, ``objects`` and ``materials``); ``"fade"`` is seconds. The settings stack from
key to key over the film's own painting (``styles.with_style``: a style, then the settings given), and each
setting, a per-object or per-material one too, has a track of its own, made of the keyframes that give it
(a style gives every setting of its look):

* a decimal setting (``lambda_p``, ``lambda_e``, ``z0``, the noises, ``grain``, ``z_max``) follows a monotone
  cubic (PCHIP, as the camera's ``fov`` does) through its keys, in the path's seconds: never beyond its
  neighbouring keys' values;
* a whole number (``iterations``, ``spp``, ``seed``), a name (``mapping``, ``method``...) or a switch
  (``hatch``) steps: the value of the last key that gives it, and before the first one the film's own;
* a decimal track holds its first key's value before it; every track holds its last key's after it.

Where the steps change at a keyframe (a style or a mapping turns into another, iterations step), the frame
cuts at the keyframe's ``t``; with ``"fade": s`` it cross-fades instead over the ``s`` seconds that end at
``t``: the frame is ``(1 - w)`` times the painting before plus ``w`` times the painting after, ``w`` rising
linearly from 0 to 1, both painted with the decimal settings of that time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.interpolate import PchipInterpolator

from ..painting.sequence import Looks
from ..settings.params import PAINT_SETTINGS, PER, PaintParams, as_dict
from ..settings.styles import STYLE, get_style, with_style

Name = tuple[str, ...]
"""A setting's place: ``("lambda_p",)``, or ``("objects", "walls", "lambda_p")`` for a per-object one."""


@dataclass(frozen=True)
class PaintKey:
    """A keyframe's painting: at ``t`` seconds, ``settings`` (the ``"paint"`` table) and its ``fade`` seconds."""

    t: float
    settings: Mapping[str, Any]
    fade: float = 0.0


def _given(settings: Mapping[str, Any]) -> set[Name]:
    """The settings a ``paint`` table sets: its own, its style's, and each per-object and per-material one."""
    names: set[Name] = {(name,) for name in settings if name not in (STYLE, *PER)}
    if settings.get(STYLE) is not None:
        names |= {(name,) for name in get_style(settings[STYLE]).settings}
    for per in PER:
        table = settings.get(per) or {}
        if not isinstance(table, Mapping):
            raise ValueError(f"{per}: give a table of names, each a table of settings")
        for name, values in table.items():
            if not isinstance(values, Mapping):
                raise ValueError(f"{per}.{name}: give a table of settings, got {values!r}")
            names |= {(per, name, key) for key in values}
    return names


def _value(params: PaintParams, name: Name):
    if len(name) == 1:
        return getattr(params, name[0])
    return dict(dict(getattr(params, name[0])).get(name[1], ()))[name[2]]


def _value_or_none(params: PaintParams, name: Name):
    """The setting's value in ``params``; for a per-object one it does not set, the setting's own there."""
    try:
        return _value(params, name)
    except KeyError:
        return getattr(params, name[-1])


def _decimal(name: Name, values: list) -> bool:
    return PAINT_SETTINGS[name[-1]].kind is float and all(isinstance(v, int | float) for v in values)


@dataclass(frozen=True)
class _Track:
    """One setting's keys: ``times (k,)`` and their values; a decimal one's curve, a step otherwise."""

    times: np.ndarray
    values: tuple
    curve: PchipInterpolator | None
    start: Any = None  # a step's value before its first key (the film's own)

    def at(self, t: float, before: bool = False):
        """The value at ``t`` (``before``: just before ``t``, the step's value before a key at ``t``)."""
        if self.curve is not None:
            return float(self.curve(np.clip(t, self.times[0], self.times[-1])))
        if len(self.values) == 1 and self.start is None:  # a decimal setting keyed once: held everywhere
            return self.values[0]
        k = int(np.searchsorted(self.times, t, side="left" if before else "right")) - 1
        return self.values[k] if k >= 0 else self.start


@dataclass(frozen=True)
class PaintTrack:
    """The painting of every moment of a path: :meth:`at` gives a frame's :data:`Looks`."""

    base: PaintParams
    tracks: dict[Name, _Track]
    fades: tuple[tuple[float, float], ...]  # (start, end) seconds of each fade where the steps change

    @classmethod
    def build(
        cls, base: PaintParams, keys: tuple[PaintKey, ...], check: Callable[[PaintParams], None] | None = None
    ) -> PaintTrack:
        """The tracks of ``keys`` (in increasing ``t``) over ``base``; ``ValueError`` in one line naming the key
        (by its place among ``keys``) whose settings cannot paint, or that ``check`` refuses."""
        params, points = base, dict[Name, list[tuple[float, Any]]]()
        for k, key in enumerate(keys):
            try:
                names = _given(key.settings)
                params = with_style(params, key.settings)
                if check is not None:
                    check(params)
            except (ValueError, TypeError) as exc:
                raise ValueError(f"{k}: {exc}") from None
            for name in names:
                points.setdefault(name, []).append((key.t, _value(params, name)))
        tracks = {}
        for name, given in points.items():
            times, values = np.array([t for t, _ in given]), tuple(v for _, v in given)
            if not _decimal(name, list(values)):
                tracks[name] = _Track(times, values, None, _value_or_none(base, name))
            elif len(times) > 1:
                tracks[name] = _Track(times, values, PchipInterpolator(times, np.asarray(values, dtype=np.float64)))
            else:
                tracks[name] = _Track(times, (float(values[0]),), None)
        track = cls(base, tracks, ())
        fades = tuple(
            (key.t - key.fade, key.t)
            for key in keys
            if key.fade > 0 and track._steps(key.t, before=True) != track._steps(key.t)
        )
        return cls(base, tracks, fades)

    def _steps(self, t: float, before: bool = False) -> tuple:
        return tuple((name, track.at(t, before)) for name, track in self.tracks.items() if track.curve is None)

    def painting(self, t: float, steps_at: float | None = None) -> PaintParams:
        """The painting at ``t``: its decimal settings at ``t``, its steps at ``steps_at`` (default ``t``)."""
        settings: dict[str, Any] = {name: getattr(self.base, name) for name in PAINT_SETTINGS}
        per: dict[str, Any] = {p: as_dict(getattr(self.base, p)) for p in PER}
        for name, track in self.tracks.items():
            value = track.at(steps_at if steps_at is not None and track.curve is None else t)
            if len(name) == 1:
                settings[name[0]] = value
            else:
                per[name[0]].setdefault(name[1], {})[name[2]] = value
        return PaintParams(**settings, **per)

    def at(self, t: float) -> Looks:
        """The painting of the frame at ``t`` seconds: one, or two blended within a fade."""
        for start, end in self.fades:
            if start < t < end:
                w = (t - start) / (end - start)
                return ((self.painting(t), 1.0 - w), (self.painting(t, steps_at=end), w))
        return ((self.painting(t), 1.0),)

    def table(self, looks: Looks) -> dict[str, Any]:
        """A frame's painting (:meth:`at`) as a ``paint`` table of the settings the keys set, for a painting that
        takes one look (the walk's): within a cross-fade the look it fades to; ``objects`` and ``materials``
        whole where a key sets one of theirs (a table replaces the earlier one)."""
        settings = looks[-1][0].settings()
        return {name: settings[name] for name in sorted({name[0] for name in self.tracks})}

    def paintings(self) -> list[PaintParams]:
        """A painting of each key's steps (each way a frame may paint, bar its decimal settings): for the limits."""
        times = sorted({float(t) for track in self.tracks.values() for t in track.times})
        return [self.painting(t) for t in times] or [self.base]
