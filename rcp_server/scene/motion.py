"""A camera's motion as a glTF animation gives it: the channels of the camera node and of its ancestors, and the
field of view where ``KHR_animation_pointer`` animates it, evaluated at any time as glTF defines.

The camera at time ``t`` is the world matrix of its node (the product of its ancestors' local matrices, each
node's translation, rotation and scale at ``t``): eye = the matrix's translation, forward = its ``-z``, up = its
``+y``; ``fov`` = ``yfov`` at ``t``, in degrees. A channel holds its first key's value before it and its last
key's after it; between keys it is ``STEP`` (the earlier key's value), ``LINEAR`` (a straight line; a rotation's
quaternions slerped the short way) or ``CUBICSPLINE`` (Hermite with the file's tangents, a rotation normalized),
as the glTF 2.0 specification says. A motion is plain data: :meth:`CameraMotion.to_json` and
:func:`motions_from_json` carry it through an uploaded scene's files, checked again there as here.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

MAX_ANIMATION_S = 400.0
"""The longest camera animation taken, in seconds: a film of it at 24 fps is within a path's 10,000 keyframes."""
MAX_ANIMATION_KEYS = 100_000
"""The most keys one channel of a camera's animation may have."""
MAX_CHAIN = 64  # ancestors of a camera node followed, at most
PATHS = {"translation": 3, "rotation": 4, "scale": 3, "yfov": 1}
INTERPOLATIONS = ("STEP", "LINEAR", "CUBICSPLINE")


class MotionError(ValueError):
    """A camera animation refused; the message is one line."""


@dataclass(frozen=True)
class Channel:
    """One animated property: key ``times (k,)`` in seconds, increasing, and ``values`` ``(k, c)`` (``(3k, c)``
    for ``CUBICSPLINE``: in-tangent, value, out-tangent per key), ``c`` the property's width."""

    path: str
    interpolation: str
    times: np.ndarray
    values: np.ndarray

    def __post_init__(self):
        k, width = len(self.times), PATHS[self.path]
        if self.interpolation not in INTERPOLATIONS:
            raise MotionError(f"{self.path}: interpolation {self.interpolation!r} is none of {INTERPOLATIONS}")
        if k == 0 or k > MAX_ANIMATION_KEYS:
            raise MotionError(f"{self.path}: {k:,} keys, where 1 to {MAX_ANIMATION_KEYS:,} are taken")
        rows = 3 * k if self.interpolation == "CUBICSPLINE" else k
        if self.values.shape != (rows, width):
            raise MotionError(f"{self.path}: {self.values.shape} values for {k} keys of {width}")
        if not (np.isfinite(self.times).all() and np.isfinite(self.values).all()):
            raise MotionError(f"{self.path}: its keys hold numbers that are not finite")
        if self.times[0] < 0 or (k > 1 and not (np.diff(self.times) > 0).all()):
            raise MotionError(f"{self.path}: its key times do not increase from 0 or more")
        if self.times[-1] > MAX_ANIMATION_S:
            raise MotionError(f"{self.path}: it lasts {self.times[-1]:g} s, more than the {MAX_ANIMATION_S:g} s taken")

    def at(self, t: np.ndarray) -> np.ndarray:
        """The property at seconds ``t (m,)``: ``(m, c)`` float64."""
        times, k = self.times, len(self.times)
        cubic = self.interpolation == "CUBICSPLINE"
        keys = self.values[1::3] if cubic else self.values
        i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, max(k - 2, 0))
        if k == 1:
            return np.repeat(keys[:1], len(t), axis=0)
        span = times[i + 1] - times[i]
        s = np.clip((t - times[i]) / span, 0.0, 1.0)[:, None]
        a, b = keys[i], keys[i + 1]
        if self.interpolation == "STEP":
            out = np.where(s >= 1.0, b, a)
        elif cubic:
            out_tangent, in_tangent = self.values[3 * i + 2], self.values[3 * (i + 1)]
            s2, s3 = s * s, s * s * s
            d = span[:, None]
            out = (
                (2 * s3 - 3 * s2 + 1) * a
                + (s3 - 2 * s2 + s) * d * out_tangent
                + (-2 * s3 + 3 * s2) * b
                + (s3 - s2) * d * in_tangent
            )
        elif self.path == "rotation":
            out = _slerp(a, b, s[:, 0])
        else:
            out = a + s * (b - a)
        if self.path == "rotation":
            out = out / np.linalg.norm(out, axis=1, keepdims=True)
        return out


def _slerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Quaternions ``(m, 4)`` a fraction ``w (m,)`` from ``a`` to ``b``, the short way."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    dot = np.einsum("ij,ij->i", a, b)
    b = np.where((dot < 0)[:, None], -b, b)
    dot = np.abs(dot)
    angle = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(angle)
    near = sin < 1e-9
    safe = np.where(near, 1.0, sin)
    wa = np.where(near, 1 - w, np.sin((1 - w) * angle) / safe)
    wb = np.where(near, w, np.sin(w * angle) / safe)
    return wa[:, None] * a + wb[:, None] * b


@dataclass(frozen=True)
class NodeMotion:
    """One node of the camera's chain: its still translation, rotation (x, y, z, w) and scale, or its ``matrix``
    (16 floats, column-major, then nothing of it moves), and the channels that animate it."""

    translation: tuple[float, ...] = (0.0, 0.0, 0.0)
    rotation: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
    scale: tuple[float, ...] = (1.0, 1.0, 1.0)
    matrix: tuple[float, ...] | None = None
    channels: tuple[Channel, ...] = ()

    def local(self, t: np.ndarray) -> np.ndarray:
        """The node's local matrices at seconds ``t (m,)``: ``(m, 4, 4)``."""
        m = len(t)
        if self.matrix is not None:
            return np.broadcast_to(np.asarray(self.matrix, np.float64).reshape(4, 4).T, (m, 4, 4))
        trs = {"translation": self.translation, "rotation": self.rotation, "scale": self.scale}
        values = {name: np.broadcast_to(np.asarray(v, np.float64), (m, len(v))) for name, v in trs.items()}
        for channel in self.channels:
            values[channel.path] = channel.at(t)
        x, y, z, w = (values["rotation"] / np.linalg.norm(values["rotation"], axis=1, keepdims=True)).T
        rotation = np.stack(
            [
                np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
                np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
                np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
            ],
            axis=1,
        )
        out = np.zeros((m, 4, 4))
        out[:, :3, :3] = rotation * values["scale"][:, None, :]
        out[:, :3, 3] = values["translation"]
        out[:, 3, 3] = 1.0
        return out


@dataclass(frozen=True)
class CameraMotion:
    """An animated camera: its ``chain`` of nodes from the root down to the camera's own, its still ``yfov``
    (radians) and the channel that animates it, if any."""

    name: str
    chain: tuple[NodeMotion, ...]
    yfov: float
    fov_channel: Channel | None = None

    def __post_init__(self):
        if not 0 < len(self.chain) <= MAX_CHAIN:
            raise MotionError(f"camera {self.name!r}: a chain of {len(self.chain)} nodes")
        if not 0 < self.yfov < math.pi:
            raise MotionError(f"camera {self.name!r}: yfov {self.yfov!r} is not between 0 and pi")

    @property
    def channels(self) -> list[Channel]:
        return [c for node in self.chain for c in node.channels] + ([self.fov_channel] if self.fov_channel else [])

    @property
    def duration(self) -> float:
        """Seconds from 0 to the last key of any of its channels."""
        return max(float(c.times[-1]) for c in self.channels)

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Eye, forward and up ``(m, 3)`` (world space, the latter two unit) and fov ``(m,)`` in degrees at
        seconds ``t (m,)``."""
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        world = np.broadcast_to(np.eye(4), (len(t), 4, 4))
        for node in self.chain:
            world = world @ node.local(t)
        eye = world[:, :3, 3]
        forward = -world[:, :3, 2]
        up = world[:, :3, 1]
        forward = forward / np.linalg.norm(forward, axis=1, keepdims=True)
        up = up / np.linalg.norm(up, axis=1, keepdims=True)
        if self.fov_channel is not None:
            fov = np.degrees(self.fov_channel.at(t)[:, 0])
        else:
            fov = np.full(len(t), math.degrees(self.yfov))
        return eye, forward, up, fov

    def to_json(self) -> dict:
        def channel(c: Channel) -> dict:
            return {"path": c.path, "interpolation": c.interpolation, "times": c.times.tolist(),
                    "values": c.values.tolist()}  # fmt: skip

        chain = [
            {"translation": n.translation, "rotation": n.rotation, "scale": n.scale, "matrix": n.matrix,
             "channels": [channel(c) for c in n.channels]}
            for n in self.chain
        ]  # fmt: skip
        fov = channel(self.fov_channel) if self.fov_channel is not None else None
        return {"name": self.name, "chain": chain, "yfov": self.yfov, "fov_channel": fov}


def _channel_of(spec: dict) -> Channel:
    path = spec["path"]
    if path not in PATHS:
        raise MotionError(f"no animated property {path!r}")
    return Channel(
        path,
        str(spec["interpolation"]),
        np.asarray(spec["times"], np.float64).reshape(-1),
        np.asarray(spec["values"], np.float64).reshape(-1, PATHS[path]),
    )


def motions_from_json(text: str) -> list[CameraMotion]:
    """Motions written by :meth:`CameraMotion.to_json` (a JSON list), checked as when they were read from the
    file; :class:`MotionError` in one line for anything else."""
    try:
        motions = []
        for spec in json.loads(text):
            chain = tuple(
                NodeMotion(
                    tuple(map(float, n["translation"])),
                    tuple(map(float, n["rotation"])),
                    tuple(map(float, n["scale"])),
                    None if n["matrix"] is None else tuple(map(float, n["matrix"])),
                    tuple(_channel_of(c) for c in n["channels"]),
                )
                for n in spec["chain"]
            )
            fov = spec["fov_channel"]
            motions.append(
                CameraMotion(
                    str(spec["name"])[:80], chain, float(spec["yfov"]), None if fov is None else _channel_of(fov)
                )
            )
        return motions
    except MotionError:
        raise
    except (ValueError, TypeError, KeyError, IndexError) as exc:
        raise MotionError(f"camera motions that cannot be read ({type(exc).__name__})") from None
