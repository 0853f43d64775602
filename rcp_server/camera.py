"""The pinhole camera and the conventions every other module follows.

Conventions (``shared/MISSION.md``; the one place they are written down in code):

* World space is right-handed. A camera is ``eye``, ``look_at``, ``up`` (default ``[0, 1, 0]``) and
  ``fov``, the *vertical* field of view in degrees (default 60).
* Camera basis: ``f = normalize(look_at - eye)``, ``r = normalize(f x up)``, ``u = r x f``.
* Images are ``width x height`` (W x H). Pixel ``(i, j)``: column ``i`` left to right, row ``j`` top to
  bottom. Arrays of pixels are row-major, so a flat pixel index is ``j * W + i`` and images are
  ``(H, W, ...)``.
* A sample of pixel ``(i, j)`` has texture coordinates ``(s, t) = ((i + xi) / W, (j + eta) / H)``.
* The image plane sits at unit distance along ``f``:
  ``P_p(s, t) = eye + f + (2s - 1) a tan(fov/2) r + (1 - 2t) tan(fov/2) u`` with ``a = W / H``; its pixel
  pitch is ``p = 2 tan(fov/2) / H``.
* Depth is view-space depth along the frame camera's ``f``: ``z = (X - eye) . f``.

A :class:`Region` is a rectangle of the full image; everything per pixel is computed from absolute pixel
coordinates, so a region renders exactly the pixels the full image has there.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

RAY_DTYPE = np.float32
"""The ray engine's dtype (Embree takes float32); geometry math is float64 until rays are built."""


COORDINATE_LIMIT = 1e9


class CameraError(ValueError):
    """A camera that cannot form a basis (eye on target, up parallel to the view, non-finite values)."""


def _vec3(name: str, value) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,):
        raise CameraError(f"{name} must be three numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def camera_faults(
    eye: np.ndarray, look_at: np.ndarray, up: np.ndarray, fov: np.ndarray
) -> tuple[np.ndarray, str | None]:
    """The rules of a valid camera, written once and checked for ``m`` cameras at once (:class:`Camera` checks
    itself with them, a camera path all of its frames): ``eye``, ``look_at``, ``up`` ``(m, 3)`` float64, scene
    units; ``fov (m,)`` degrees. Returns ``bad (m,)`` bool and the one-line reason of the first bad camera
    (None when all are valid)."""
    faults: list[tuple[np.ndarray, Callable[[int], str]]] = []  # (m,) mask, the reason for camera k
    with np.errstate(all="ignore"):
        for name, v in (("eye", eye), ("look_at", look_at), ("up", up)):
            faults.append((~np.isfinite(v).all(axis=1), partial(_reason, f"{name} must be finite, got", v)))
            # past this, float32 rays and the basis's norms break down
            outside = ~(np.abs(v) <= COORDINATE_LIMIT).all(axis=1)
            limit = f"{name} must lie within +-{COORDINATE_LIMIT:g} scene units, got"
            faults.append((outside, partial(_reason, limit, v)))
        angle = "fov must be a vertical angle in degrees strictly between 0 and 180, got"
        faults.append((~((fov > 0.0) & (fov < 180.0)), partial(_reason, angle, fov)))
        view = look_at - eye
        reach = np.linalg.norm(view, axis=1)
        up_length = np.linalg.norm(up, axis=1)
        side = np.linalg.norm(np.cross(view / reach[:, None], up / up_length[:, None]), axis=1)
    for broken, reason in (
        (~(reach >= 1e-9), "eye and look_at coincide: the camera has no view direction"),
        (~(up_length >= 1e-9), "up must not be the zero vector"),
        (~(side >= 1e-6), "up is parallel to the view direction: the camera has no right vector"),
    ):
        faults.append((broken, partial(_fixed, reason)))
    bad = np.logical_or.reduce([broken for broken, _ in faults])
    if not bad.any():
        return bad, None
    first = int(np.argmax(bad))
    return bad, next(say(first) for broken, say in faults if broken[first])


def _fixed(reason: str, k: int) -> str:
    return reason


def _reason(what: str, values: np.ndarray, k: int) -> str:
    value = values[k]
    shown = f"{float(value):g}" if value.ndim == 0 else "(" + ", ".join(f"{float(x)!r}" for x in value) + ")"
    return f"{what} {shown}"


@dataclass(frozen=True)
class Camera:
    """A pinhole camera; validated on construction so every later step can trust its basis."""

    eye: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 60.0

    def __post_init__(self):
        for name in ("eye", "look_at", "up"):
            object.__setattr__(self, name, _vec3(name, getattr(self, name)))
        object.__setattr__(self, "fov", float(self.fov))
        _, reason = camera_faults(*(np.array([v]) for v in (self.eye, self.look_at, self.up, self.fov)))
        if reason is not None:
            raise CameraError(reason)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(r, u, f)``: right, up and forward unit vectors, each (3,) float64."""
        f = np.subtract(self.look_at, self.eye)
        f = f / np.linalg.norm(f)
        r = np.cross(f, self.up)
        r = r / np.linalg.norm(r)
        return r, np.cross(r, f), f

    def half_height(self) -> float:
        """``tan(fov / 2)``: half the image plane's height at unit distance."""
        return math.tan(math.radians(self.fov) / 2.0)

    def pixel_pitch(self, height: int) -> float:
        """``p = 2 tan(fov/2) / H``: one pixel's size on the unit-distance image plane, in scene units."""
        return 2.0 * self.half_height() / height

    def moved(self, **changes) -> Camera:
        return replace(self, **changes)  # validated again, in __post_init__


@dataclass(frozen=True)
class Region:
    """The pixels ``[x0, x0 + width) x [y0, y0 + height)`` of a ``full_width x full_height`` image."""

    full_width: int
    full_height: int
    x0: int = 0
    y0: int = 0
    width: int = field(default=-1)
    height: int = field(default=-1)

    def __post_init__(self):
        if self.width < 0:
            object.__setattr__(self, "width", self.full_width - self.x0)
        if self.height < 0:
            object.__setattr__(self, "height", self.full_height - self.y0)
        if self.full_width < 1 or self.full_height < 1:
            raise ValueError(f"image size must be at least 1x1, got {self.full_width}x{self.full_height}")
        if not (
            0 <= self.x0
            and self.x0 + self.width <= self.full_width
            and self.width >= 1
            and 0 <= self.y0
            and self.y0 + self.height <= self.full_height
            and self.height >= 1
        ):
            raise ValueError(f"region {self} lies outside the {self.full_width}x{self.full_height} image")

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @property
    def pixel_count(self) -> int:
        return self.width * self.height

    def pixel_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """``(i, j)``: absolute column and row of each pixel of the region, row-major, each (n,) int64."""
        j, i = np.mgrid[self.y0 : self.y0 + self.height, self.x0 : self.x0 + self.width]
        return i.ravel().astype(np.int64), j.ravel().astype(np.int64)

    def tiles(self, rows: int) -> list[Region]:
        """Horizontal bands of at most ``rows`` rows covering this region."""
        return [
            Region(self.full_width, self.full_height, self.x0, y, self.width, min(rows, self.y0 + self.height - y))
            for y in range(self.y0, self.y0 + self.height, rows)
        ]


def plane_points(camera: Camera, region: Region, s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Image-plane points ``P_p(s, t)`` for texture coordinates ``s, t`` ((n,) float64): (n, 3) float64."""
    r, u, f = camera.basis()
    tan_half = camera.half_height()
    aspect = region.full_width / region.full_height
    sx = ((2.0 * s - 1.0) * aspect * tan_half)[:, None]
    ty = ((1.0 - 2.0 * t) * tan_half)[:, None]
    return np.asarray(camera.eye) + f + sx * r + ty * u
