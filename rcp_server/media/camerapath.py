"""Camera paths: keyframed views in time, and the cameras of a video's frames between them.

The one JSON format of the client, ``rcp render --path`` and ``POST /api/videos``::

    {"fps": 24, "loop": false, "keyframes": [
        {"t": 0.0, "eye": [x, y, z], "look_at": [x, y, z], "up": [0, 1, 0], "fov": 60, "scene_time": 0.0}, ...]}

``t`` is seconds along the path and increases from keyframe to keyframe, by :data:`MIN_GAP` at least (the
first at ``t >= 0``; before it the camera holds). ``up`` and ``fov`` may be left out: the previous keyframe's,
and for the first one the scene camera's. ``scene_time`` (seconds of the scene's animation) may be left out:
the scene's clock then runs on with ``t`` from the previous keyframe's (so a path that gives none has
``scene_time = t``).

``ease`` (``[in, out]``, each 0 to 1, default 0) slows the camera into and out of a keyframe: between keyframes
``k`` and ``k + 1`` the curves are read at ``t_k + f(s) (t_{k+1} - t_k)``, ``s`` the fraction of the segment gone
and ``f`` the cubic from 0 to 1 whose slope is ``1 - out_k`` at its start and ``1 - in_{k+1}`` at its end (1:
the camera comes to rest there). The painting's keys follow the same eased time; the scene's clock does not.

Frames are taken every ``1 / fps`` seconds from ``t = 0`` to the last keyframe's ``t``, both included (the
last one when it falls on that grid). With ``loop``, the path closes: after the last keyframe it returns to
the first keyframe's view over one mean keyframe interval, every curve is periodic, and the frames stop just
before the closing time, whose frame would repeat the first one: the video plays in a seamless loop.

Between keyframes (all curves pass through the keyframes at their times, with no overshoot in the scalars):

* The eye follows a centripetal Catmull-Rom spline (knots spaced by the square root of the chord), which
  has no cusps or self-intersections within a segment. The knot parameter is mapped to time by a monotone
  cubic (PCHIP) through ``(t_i, knot_i)``, so the eye's velocity is continuous in time, including at the
  keyframes, and zero where the eye rests (two keyframes at the same eye).
* The view (forward and up together, as one rotation) follows a cubic rotation spline: continuous angular
  velocity, the shortest turn between consecutive keyframes, so it never flips or rolls over.
* The distance to ``look_at`` (the depth mapping's default focus), ``fov`` and ``scene_time`` follow PCHIP:
  smooth, and never beyond their neighbouring keyframes' values.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, replace
from typing import Annotated, Any, NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model
from scipy.interpolate import PchipInterpolator
from scipy.spatial.transform import Rotation, RotationSpline

from ..camera.camera import Camera, CameraError, camera_faults
from ..camera.wire import camera_fields
from ..scene.motion import CameraMotion
from ..scene.scenefile import one_line
from ..settings.params import PaintParams
from .keyedpaint import Looks, PaintKey, PaintTrack

MAX_FRAMES = 100_000
"""The most frames one path may give (over an hour at 24 fps): a bound on what a path file can ask for."""
MAX_KEYFRAMES = 10_000
MAX_FPS = 240.0
MAX_DURATION = 24 * 3600.0  # seconds along a path
MIN_GAP = 1e-3
"""Seconds between consecutive keyframes, at least: closer ones are no view a video could show (a frame at the
highest fps lasts 4 ms), and a curve's slopes through them overflow."""


Unit = Annotated[float, Field(allow_inf_nan=False, ge=0, le=1)]


class PathError(ValueError):
    """A camera path that cannot be used; the message is one line naming the bad field."""


# ---- the file format ----


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


HELD = ("projection", "stereo", "ipd", "eyes")
"""Camera fields a path holds from start to end (a video is one projection): given once, or given alike."""
CARRIED = frozenset({"up", "fov", *HELD})
"""Camera fields a keyframe may leave out: then as the keyframe before (at first, the scene camera's)."""

KeyframeSpec = create_model(  # type: ignore[call-overload]  # its camera is declared once, in camera.py
    "KeyframeSpec",
    __base__=_Model,
    __doc__="One keyframe: the camera's view at ``t`` seconds along the path (``fov`` vertical, in degrees).",
    t=(Annotated[float, Field(allow_inf_nan=False, ge=0, le=MAX_DURATION)], ...),
    **camera_fields(optional=CARRIED),
    scene_time=(Annotated[float, Field(allow_inf_nan=False, ge=0, le=1e6)] | None, None),
    paint=(dict[str, Any] | None, None),
    ease=(tuple[Unit, Unit] | None, None),
    fade=(Annotated[float, Field(allow_inf_nan=False, ge=0, le=MAX_DURATION)] | None, None),
)


class PathSpec(_Model):
    """A camera path as written: frames per second, two or more keyframes in increasing ``t``, ``loop``."""

    fps: Annotated[float, Field(allow_inf_nan=False, gt=0, le=MAX_FPS)] = 24.0
    keyframes: Annotated[list[KeyframeSpec], Field(min_length=2, max_length=MAX_KEYFRAMES)]  # type: ignore[valid-type]
    loop: bool = False

    def resolve(self, scene_camera: Camera) -> CameraPath:
        """The path with every default filled in (``up`` and ``fov`` from ``scene_camera`` where no earlier
        keyframe gives them), checked as a whole, for everything a video of it will ask: increasing ``t`` at
        least :data:`MIN_GAP` apart, valid cameras, a bounded frame count, curves that fit, and a valid camera
        at every frame (:meth:`CameraPath.check`). Raises :class:`PathError`."""
        keyframes: list[Any] = list(self.keyframes)  # models built from the camera declaration
        for k in range(1, len(keyframes)):
            if not keyframes[k].t >= keyframes[k - 1].t + MIN_GAP:
                raise PathError(
                    f"keyframes.{k}.t: must be greater than the previous keyframe's t, by {MIN_GAP:g} s at least "
                    f"({keyframes[k].t:g} after {keyframes[k - 1].t:g})"
                )
        carried = {name: getattr(scene_camera, name) for name in CARRIED}
        for name in HELD:  # the one value every keyframe then has
            given = [(k, value) for k, key in enumerate(keyframes) if (value := getattr(key, name)) is not None]
            for k, value in given[1:]:
                if value != given[0][1]:
                    raise PathError(
                        f"keyframes.{k}.{name}: a path keeps one {name} from start to end, "
                        f"and keyframe {given[0][0]} gave {given[0][1]!r}"
                    )
            if given:
                carried[name] = given[0][1]
        times: list[float] = []
        cameras: list[Camera] = []
        scene_times: list[float] = []
        paints: list[PaintKey] = []
        eases = tuple(tuple(key.ease) if key.ease is not None else (0.0, 0.0) for key in keyframes)
        for k, key in enumerate(keyframes):
            if key.fade is not None and (key.paint is None or k == 0 or key.fade > key.t - keyframes[k - 1].t):
                raise PathError(
                    f"keyframes.{k}.fade: a fade belongs to a keyframe with a paint table, and lasts at most "
                    "the time since the keyframe before"
                )
            if key.paint is not None:
                paints.append(PaintKey(key.t, key.paint, key.fade or 0.0))
            carried.update({name: value for name in ("up", "fov") if (value := getattr(key, name)) is not None})
            try:
                cameras.append(Camera(key.eye, key.look_at, **carried))
            except CameraError as exc:
                raise PathError(f"keyframes.{k}: {exc}") from None
            if key.scene_time is not None:
                scene_times.append(key.scene_time)
            else:
                scene_times.append(key.t if k == 0 else scene_times[-1] + key.t - times[-1])
            times.append(key.t)
        path = CameraPath(self.fps, tuple(times), tuple(cameras), tuple(scene_times), self.loop, tuple(paints),
                          eases=eases if any(any(e) for e in eases) else ())  # fmt: skip
        path.with_painting(PaintParams())  # the settings checked (the scene's objects, when it paints)
        if path.frame_count > MAX_FRAMES:
            raise PathError(
                f"keyframes: {path.duration:g} s at {self.fps:g} fps is {path.frame_count:,} frames, "
                f"more than the {MAX_FRAMES:,} a path may have"
            )
        path.check()
        return path


def parse_path(source: str | bytes | dict) -> PathSpec:
    """A path from JSON text or an already decoded object; raises :class:`PathError` in one line."""
    try:
        if isinstance(source, dict):
            return PathSpec.model_validate(source)
        return PathSpec.model_validate_json(source)
    except ValidationError as exc:
        raise PathError(one_line(exc)) from None


def load_path(file, scene_camera: Camera, fps: float | None = None) -> CameraPath:
    """A path file, resolved against the scene's camera (``fps``, when given, in place of the file's); every
    fault is a :class:`PathError` naming the file."""
    try:
        with open(file, "rb") as handle:
            text = handle.read(MAX_KEYFRAMES * 1024)
    except OSError as exc:
        raise PathError(f"{file}: {exc.strerror or exc}") from None
    try:
        spec = parse_path(text)
        if fps is not None:
            spec = parse_path({**spec.model_dump(), "fps": fps})
        return spec.resolve(scene_camera)
    except PathError as exc:
        raise PathError(f"{file}: {exc}") from None


# ---- the path between keyframes ----


class PathFrame(NamedTuple):
    """One frame of a path: its index, seconds along the path, the camera, the scene's time, and the painting
    that its path keys (``keyedpaint.Looks``; empty: the film's own)."""

    index: int  # type: ignore[assignment]  # the frame's number, in place of tuple.index (which nobody calls)
    t: float
    camera: Camera
    scene_time: float
    looks: Looks = ()


def _centripetal_knots(points: np.ndarray) -> np.ndarray:
    """Knots ``(n,)`` spaced by the square root of the distance between consecutive ``points (n, 3)``."""
    return np.concatenate([[0.0], np.cumsum(np.sqrt(np.linalg.norm(np.diff(points, axis=0), axis=1)))])


def _catmull_rom(points: np.ndarray, knots: np.ndarray, segment: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Points ``(m, 3)`` on the Catmull-Rom curve through ``points (n, 3)`` with ``knots (n,)``, at knot
    values ``k (m,)`` in segments ``segment (m,)`` (segment i runs from point i to i + 1, 1 <= i <= n - 3: the
    first and last points only shape the ends). Barry and Goldman's pyramid; a segment of zero length is its
    point, and a zero-length neighbour chord is replaced by the reflection of the other side."""
    i = segment
    p0, p1, p2, p3 = points[i - 1], points[i], points[i + 1], points[i + 2]
    k0, k1, k2, k3 = knots[i - 1], knots[i], knots[i + 1], knots[i + 2]
    # a neighbour on the same spot as its end gives no direction: reflect the segment through that end instead
    flat0 = k1 - k0 <= 0
    p0 = np.where(flat0[:, None], 2 * p1 - p2, p0)
    k0 = np.where(flat0, k1 - (k2 - k1), k0)
    flat3 = k3 - k2 <= 0
    p3 = np.where(flat3[:, None], 2 * p2 - p1, p3)
    k3 = np.where(flat3, k2 + (k2 - k1), k3)
    still = k2 - k1 <= 0
    span = np.where(still, 1.0, k2 - k1)
    k0 = np.where(still, k1 - 1.0, k0)
    k3 = np.where(still, k2 + 1.0, k3)

    def lerp(a, b, ka, kb):
        w = ((k - ka) / (kb - ka))[:, None]
        return a + w * (b - a)

    a1, a2, a3 = lerp(p0, p1, k0, k1), lerp(p1, p2, k1, k1 + span), lerp(p2, p3, k2, k3)
    b1, b2 = lerp(a1, a2, k0, k1 + span), lerp(a2, a3, k1, k3)
    c = lerp(b1, b2, k1, k1 + span)
    return np.where(still[:, None], p1, c)


@dataclass(frozen=True)
class CameraPath:
    """A resolved path: ``times (n,)`` seconds, increasing, with a valid camera and a scene time each."""

    fps: float
    times: tuple[float, ...]
    cameras: tuple[Camera, ...]
    scene_times: tuple[float, ...]
    loop: bool = False
    paints: tuple[PaintKey, ...] = ()  # the keyframes' paint tables, in increasing t
    track: PaintTrack | None = None  # the painting along the path, over a film's own (:meth:`with_painting`)
    eases: tuple[tuple[float, float], ...] = ()  # (in, out) of each keyframe, or () for none

    def timing(self, t: np.ndarray) -> np.ndarray:
        """Seconds ``t (m,)`` as the curves read them: each segment's time eased by its keyframes (see the
        module's docstring); ``t`` itself without eases."""
        t = np.asarray(t, dtype=np.float64)
        if not self.eases:
            return t
        times = np.asarray(self.times)
        k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
        span = times[k + 1] - times[k]
        s = np.clip((t - times[k]) / span, 0.0, 1.0)
        leave = 1.0 - np.array([e[1] for e in self.eases])[k]  # the speed leaving key k
        arrive = 1.0 - np.array([e[0] for e in self.eases])[k + 1]  # and arriving at key k + 1
        eased = (s**3 - 2 * s**2 + s) * leave + (-2 * s**3 + 3 * s**2) + (s**3 - s**2) * arrive
        inside = (t > times[0]) & (t < times[-1])
        return np.where(inside, times[k] + eased * span, t)

    def with_painting(self, base: PaintParams, check: Callable[[PaintParams], None] | None = None) -> CameraPath:
        """This path painting its keyed settings over ``base`` (the film's painting; unchanged if it keys none):
        its frames then carry their :data:`Looks`. ``check`` (a scene's ``check_names``) refuses what the scene
        cannot paint. Raises :class:`PathError` naming the keyframe."""
        if not self.paints:
            return self
        try:
            track = PaintTrack.build(base, self.paints, check)
        except ValueError as exc:
            k, _, reason = str(exc).partition(": ")
            key = [t for t in self.times].index(self.paints[int(k)].t)
            raise PathError(f"keyframes.{key}.paint: {reason}") from None
        return replace(self, track=track)

    @property
    def end(self) -> float:
        """Seconds at which the path ends: the last keyframe's ``t``, or with ``loop`` the closing time."""
        if not self.loop:
            return self.times[-1]
        return self.times[-1] + (self.times[-1] - self.times[0]) / (len(self.times) - 1)

    @property
    def duration(self) -> float:
        return self.end

    @property
    def frame_count(self) -> int:
        """Frames at ``k / fps`` from 0 to :attr:`end` (excluded with ``loop``: it repeats frame 0)."""
        steps = self.end * self.fps
        if self.loop:
            return max(1, math.ceil(steps - 1e-9))
        return math.floor(steps + 1e-9) + 1

    def check(self) -> None:
        """Fits the curves and checks the camera of every frame, all at once (a fraction of a second for the
        longest path): a path that passes paints every one of its frames. Raises :class:`PathError` naming the
        first frame whose camera is not valid (the curves between keyframes near the coordinate limit can
        reach past it)."""
        try:
            with np.errstate(all="ignore"):
                curves = self._curves()
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise PathError(f"keyframes: no smooth path passes through them ({' '.join(str(exc).split())})") from None
        times = self.frame_times()
        with np.errstate(all="ignore"):
            eye, look_at, up = curves.view(self.timing(times))
            fov, scene_time = curves.fov(self.timing(times)), curves.scene_time(times)
        bad, reason = camera_faults(eye, look_at, up, fov)
        if reason is None and not np.isfinite(scene_time).all():
            bad, reason = ~np.isfinite(scene_time), "its scene_time is not a finite number"
        if reason is not None:
            k = int(np.argmax(bad))
            raise PathError(
                f"keyframes: the camera of frame {k} (t = {times[k]:g} s), between them, is not valid: {reason}"
            )

    def frame_times(self) -> np.ndarray:
        """Seconds along the path of every frame, ``(frame_count,)`` float64."""
        return np.arange(self.frame_count, dtype=np.float64) / self.fps

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[PathFrame]:
        """The frames ``start`` to ``stop`` (default all), in order, computed in chunks (a path is lazy)."""
        stop = self.frame_count if stop is None else min(stop, self.frame_count)
        times = self.frame_times()
        for first in range(start, stop, 1024):
            chunk = times[first : min(stop, first + 1024)]
            rows = zip(chunk, *self.at(chunk), self.looks(chunk), strict=True)
            for n, (t, camera, scene_time, looks) in enumerate(rows):
                yield PathFrame(first + n, float(t), camera, scene_time, looks)

    def looks(self, t: np.ndarray) -> list[Looks]:
        """The painting of the frames at seconds ``t (m,)``: the keyed one (:meth:`with_painting`) at each one's
        time as the camera's eases read it, or ``()`` each (the film's own)."""
        if self.track is None:
            return [()] * len(t)
        eased = self.timing(np.minimum(np.asarray(t, dtype=np.float64), self.end))
        return [self.track.at(float(s)) for s in eased]

    def keyed_paint(self, t: np.ndarray) -> list[dict[str, Any]]:
        """What the path keys at seconds ``t (m,)`` over the film's painting, one ``paint`` table each
        (:meth:`.PaintTrack.table`: within a cross-fade, the painting it fades to); ``[]`` when it keys none."""
        if self.track is None:
            return []
        return [self.track.table(looks) for looks in self.looks(t)]

    def at(self, t: np.ndarray) -> tuple[list[Camera], list[float]]:
        """Cameras and scene times at seconds ``t (m,)`` along the path (held before the first keyframe)."""
        raw = np.clip(np.asarray(t, dtype=np.float64), self.times[0], self.end)
        t = self.timing(raw)
        curves = self._curves()
        eye, look_at, up = curves.view(t)
        fov, scene_time = curves.fov(t), curves.scene_time(raw)  # the scene's clock is not eased
        held = {name: getattr(self.cameras[0], name) for name in HELD}  # the same in every keyframe
        cameras = [
            Camera(tuple(e), tuple(a), tuple(u), float(f), **held)
            for e, a, u, f in zip(eye, look_at, up, fov, strict=True)
        ]
        return cameras, [float(s) for s in scene_time]

    def _curves(self) -> _Curves:
        cached = self.__dict__.get("_cached_curves")
        if cached is None:
            cached = _Curves.fit(self)
            object.__setattr__(self, "_cached_curves", cached)  # a cache, not state: the path stays frozen
        return cached

    def to_json(self) -> str:
        """The resolved path in the file format (every default written out)."""
        keyframes = [
            {"t": t, **asdict(c), "scene_time": s}
            for t, c, s in zip(self.times, self.cameras, self.scene_times, strict=True)
        ]
        return json.dumps({"fps": self.fps, "keyframes": self.keyed(keyframes), "loop": self.loop})

    def keyed(self, keyframes: list[dict]) -> list[dict]:
        """``keyframes`` (one dict a keyframe, written out) with their ``paint``, ``fade`` and ``ease`` as given."""
        by_time = {key.t: key for key in self.paints}
        for keyframe, ease in zip(keyframes, self.eases, strict=False):
            if any(ease):
                keyframe["ease"] = list(ease)
        for keyframe in keyframes:
            key = by_time.get(keyframe["t"])
            if key is not None:
                keyframe["paint"] = dict(key.settings)
                if key.fade:
                    keyframe["fade"] = key.fade
        return keyframes


@dataclass(frozen=True)
class _Spline:
    """A centripetal Catmull-Rom curve through points at times, as a function of seconds ``(m,)`` -> ``(m, 3)``.
    ``points (n, 3)`` and ``times (n,)`` include one neighbour beyond each end, which only shapes the ends."""

    points: np.ndarray
    knots: np.ndarray
    knot_of_time: PchipInterpolator

    @classmethod
    def through(cls, points: np.ndarray, times: np.ndarray) -> _Spline:
        knots = _centripetal_knots(points)
        return cls(points, knots, PchipInterpolator(times, knots))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        k = np.clip(self.knot_of_time(t), self.knots[1], self.knots[-2])
        # at a knot shared by a resting segment either segment gives the same point
        segment = np.clip(np.searchsorted(self.knots, k, side="right") - 1, 1, len(self.knots) - 3)
        return _catmull_rom(self.points, self.knots, segment, k)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class _Curves:
    """The fitted curves of a path, each a function of seconds ``(m,)``."""

    eye: _Spline
    target: _Spline
    rotation: RotationSpline
    distance: PchipInterpolator
    fov: PchipInterpolator
    scene_time: PchipInterpolator

    def view(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eye, look-at point and up vector at seconds ``t (m,)``, each ``(m, 3)``.

        The view looks at the look-at points' own spline, so an orbit keeps its target on screen; where that
        direction strays from the rotation spline's (the eye passing its target, a turn on the spot) the
        view blends smoothly into the rotation spline's, which cannot flip. The blend weight is 1 at every
        keyframe, where both directions are the keyframe's."""
        eye, target = self.eye(t), self.target(t)
        rotation = self.rotation(t).as_matrix()  # columns: right, up, backward (the view looks down -z)
        turned, up = -rotation[:, :, 2], rotation[:, :, 1]
        distance = self.distance(t)
        offset = target - eye
        reach = np.linalg.norm(offset, axis=1)
        aimed = offset / np.maximum(reach, 1e-300)[:, None]
        agree = np.einsum("ij,ij->i", aimed, turned)
        # fully the look-at spline's within 25 degrees of the rotation's and at half the distance or more;
        # fully the rotation's beyond 60 degrees or under a fifth of the distance
        w = _smoothstep((agree - 0.5) / (0.906 - 0.5)) * _smoothstep((reach / distance - 0.2) / 0.3)
        forward = _slerp(turned, aimed, w)
        look_at = eye + forward * ((1 - w) * distance + w * reach)[:, None]
        return eye, look_at, up

    @classmethod
    def fit(cls, path: CameraPath) -> _Curves:
        times = np.asarray(path.times)
        eyes = np.array([c.eye for c in path.cameras])
        targets = np.array([c.look_at for c in path.cameras])
        rotations = Rotation.from_matrix(np.stack([_view_matrix(c) for c in path.cameras]))
        distance = np.linalg.norm(targets - eyes, axis=1)
        fov = np.array([c.fov for c in path.cameras])
        scene_time = np.asarray(path.scene_times)
        n = len(times)
        if path.loop:
            # close the path with the first view after one mean interval, and wrap the ends (one keyframe on
            # each side is all a local curve needs; the rotation spline is global, so it gets the whole loop
            # on either side)
            period = path.end - times[0]
            closing = scene_time[-1] + path.end - times[-1]
            wrap = np.r_[n - 1, np.arange(n), 0, 1]
            times_wrapped = times[wrap] + np.r_[-period, np.zeros(n), period, period]
            rotation = RotationSpline(
                np.r_[times - period, times, times + period, times[0] + 2 * period],
                rotations[np.r_[wrap[1:-2], wrap[1:-2], wrap[1:-2], 0]],
            )
            eye = _Spline.through(eyes[wrap], times_wrapped)
            target = _Spline.through(targets[wrap], times_wrapped)
            # the scene's clock runs on through the closing segment and, before the first keyframe, as long
            scene_time = np.r_[
                scene_time[0] - (closing - scene_time[-1]), scene_time, closing, closing + scene_time[1] - scene_time[0]
            ]
            times, distance, fov = times_wrapped, distance[wrap], fov[wrap]
        else:
            # phantom neighbours beyond the ends: the reflections of the second and second-to-last keyframes
            rotation = RotationSpline(times, rotations)
            ends = np.r_[2 * times[0] - times[1], times, 2 * times[-1] - times[-2]]

            def padded(p):
                return np.concatenate([2 * p[:1] - p[1:2], p, 2 * p[-1:] - p[-2:-1]])

            eye, target = _Spline.through(padded(eyes), ends), _Spline.through(padded(targets), ends)
        return cls(
            eye=eye,
            target=target,
            rotation=rotation,
            distance=PchipInterpolator(times, distance),
            fov=PchipInterpolator(times, fov),
            scene_time=PchipInterpolator(times, scene_time),
        )


def _slerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Unit vectors ``(m, 3)`` a fraction ``w (m,)`` of the way along the great circle from ``a`` to ``b``
    (unit, ``(m, 3)``, never opposite where ``w > 0``)."""
    cos = np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)
    angle = np.arccos(cos)
    sin = np.sin(angle)
    small = sin < 1e-9
    safe = np.where(small, 1.0, sin)
    wa = np.where(small, 1 - w, np.sin((1 - w) * angle) / safe)
    wb = np.where(small, w, np.sin(w * angle) / safe)
    v = wa[:, None] * a + wb[:, None] * b
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _view_matrix(camera: Camera) -> np.ndarray:
    """The camera's orientation, (3, 3): columns right, up and backward (``-f``), a proper rotation."""
    r, u, f = camera.basis()
    return np.stack([r, u, -f], axis=1)


# ---- a path from an animated camera (a glTF's) ----

CAMERA_PREFIX = "camera:"
"""How a path names a scene's animated camera in place of a file or keyframes: ``camera:NAME``."""


def motion_path(ref: str, motions: Mapping[str, CameraMotion], fps: float | None, distance: float) -> CameraPath:
    """The path of the animated camera ``ref`` (``camera:NAME``) among a scene's ``motions``: one keyframe a frame,
    every ``1 / fps`` seconds (default 24) from 0 to the animation's end, each the animation's camera at that time
    (looking at ``distance`` along its view, the depth mapping's default focus), the scene's clock with it. The
    path's curves pass through their keyframes, so every frame is the animation's camera. :class:`PathError` in
    one line for an unknown name or an animation too long for a path."""
    name = ref.removeprefix(CAMERA_PREFIX)
    motion = motions.get(name)
    if motion is None:
        have = ", ".join(repr(n) for n in list(motions)[:12]) or "none"
        raise PathError(f"{ref}: the scene has no animated camera {name!r} (it has: {have})")
    fps = 24.0 if fps is None else fps
    if not 0 < fps <= MAX_FPS:
        raise PathError(f"{ref}: fps must be more than 0 and at most {MAX_FPS:g}, got {fps:g}")
    count = math.floor(motion.duration * fps + 1e-9) + 1
    if count < 2:
        raise PathError(f"{ref}: its animation lasts {motion.duration:g} s, less than one frame at {fps:g} fps")
    if count > MAX_KEYFRAMES:
        raise PathError(
            f"{ref}: {motion.duration:g} s at {fps:g} fps is {count:,} frames, more than the {MAX_KEYFRAMES:,} "
            "keyframes a path may have"
        )
    times = np.arange(count) / fps
    eye, forward, up, fov = motion.at(times)
    try:
        cameras = tuple(
            Camera(_triple(e), _triple(e + distance * f), _triple(u), float(v))
            for e, f, u, v in zip(eye, forward, up, fov, strict=True)
        )
    except CameraError as exc:
        raise PathError(f"{ref}: {exc}") from None
    path = CameraPath(fps, tuple(map(float, times)), cameras, tuple(map(float, times)))
    path.check()
    return path


def _triple(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))
