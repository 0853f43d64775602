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

Other projections (``shared/MISSION.md``, "Other projections"): a projection maps a sample to a target at
unit distance from its pixel's eye and a local frame ``(r_ij, u_ij, f_ij)`` (the pixel centre's); ``V_p`` and
``V_e`` are built in that frame and depth is ``z = (X - eye_ij) . f_ij``.

* ``perspective``: the image plane above, ``(r_ij, u_ij, f_ij) = (r, u, f)``.
* ``equirect``: longitude ``phi = (2s - 1) pi``, latitude ``theta = (1 - 2t) pi / 2``,
  ``f_ij = d = cos(theta) sin(phi) r + sin(theta) u + cos(theta) cos(phi) f``, ``r_ij = cos(phi) r - sin(phi) f``,
  ``u_ij = r_ij x f_ij``; ``W = 2H``; pitch ``p = pi / H``; ``fov`` does not apply. Its inverse map takes a
  direction back to ``phi = atan2(d . r, d . f)``, ``theta = asin(d . u)``.
* ``stereo``: ``width x height`` is one eye's image; the painting holds both, ``top-bottom`` (``W x 2H``, left
  eye on top) or ``side-by-side`` (``2W x H``, left eye on the left). Pixel ``(i, j)`` of the painting is pixel
  ``(i mod W, j mod H)`` of its eye's image, and ``(s, t)`` are that eye's. The left eye of a pixel sits at
  ``eye - (ipd/2) r_ij``, the right one at ``eye + (ipd/2) r_ij``: for ``perspective`` two parallel cameras
  ``ipd`` apart, for ``equirect`` omnidirectional stereo (each column's eye on its own right vector).
  Added here: a stereo painting's focus depth ``z0`` and the depth of a miss are the centre eye's; with
  ``eyes = "shared"`` the right eye reads its displacement fields from the left eye's previous image where the
  left eye sees the same surface point in the plain render (``stereo.py``).

A :class:`Region` is a rectangle of the full image; everything per pixel is computed from absolute pixel
coordinates, so a region renders exactly the pixels the full image has there.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields, replace
from functools import partial
from typing import Any

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


PROJECTIONS = ("perspective", "equirect")
"""What the image is a picture of: the image plane, or the whole sphere around the eye (module docstring)."""
STEREO = ("mono", "top-bottom", "side-by-side")
"""One eye, or both in one image: left over right, or left beside right."""
EYES = ("own", "shared")
"""Where each eye of a stereo painting reads its displacement fields (``stereo.py``)."""
SIDES = {"mono": (0,), "top-bottom": (-1, 1), "side-by-side": (-1, 1)}
"""The eyes of a painting, left (-1) to right (1), in the order its image holds them."""


def camera_field(help: str, default=MISSING, **bounds) -> Any:
    """A field of :class:`Camera`: its default (none: required), one line of help and its bounds (``ge``, ``gt``,
    ``lt``, ``le`` for numbers, ``choices`` for names). The wire model, a path's keyframes, the options of
    ``rcp render`` and the client's copy are derived from these (:data:`CAMERA_FIELDS`)."""
    return field(default=default, metadata={"help": help, **bounds})


@dataclass(frozen=True)
class Camera:
    """A camera, declared once: validated on construction so every later step can trust its basis."""

    eye: tuple[float, float, float] = camera_field("where the camera stands, scene units")
    look_at: tuple[float, float, float] = camera_field("the point it looks at: the centre of the view")
    up: tuple[float, float, float] = camera_field("which way is up", default=(0.0, 1.0, 0.0))
    fov: float = camera_field("vertical field of view, degrees (perspective)", default=60.0, gt=0.0, lt=180.0)
    projection: str = camera_field(
        "perspective (an image plane) or equirect (all around: 360 x 180, width = 2 x height)",
        default="perspective",
        choices=PROJECTIONS,
    )
    stereo: str = camera_field(
        "mono, or both eyes in one image: top-bottom (left on top) or side-by-side (left on the left)",
        default="mono",
        choices=STEREO,
    )
    ipd: float = camera_field("distance between the eyes of a stereo camera, scene units", default=0.064, ge=0.0)
    eyes: str = camera_field(
        "stereo: each eye smudges from its own previous image (own), or as the left eye does where both see the "
        "same point (shared: no rivalry in a headset)",
        default="own",
        choices=EYES,
    )

    def __post_init__(self):
        for name in ("eye", "look_at", "up"):
            object.__setattr__(self, name, _vec3(name, getattr(self, name)))
        object.__setattr__(self, "fov", float(self.fov))
        _, reason = camera_faults(*(np.array([v]) for v in (self.eye, self.look_at, self.up, self.fov)))
        if reason is None:
            reason = _choice_fault(self)
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
        """``p``, one pixel's size at unit distance for an eye's image ``height`` pixels high, in scene units:
        ``2 tan(fov/2) / H`` on the image plane, ``pi / H`` on the sphere (at the equator)."""
        if self.projection == "equirect":
            return math.pi / height
        return 2.0 * self.half_height() / height

    @property
    def sides(self) -> tuple[int, ...]:
        """The eyes this camera paints (:data:`SIDES`)."""
        return SIDES[self.stereo]

    def image_size(self, width: int, height: int) -> tuple[int, int]:
        """The painting's size for an eye's image of ``width x height``; raises :class:`CameraError` for a size
        this projection cannot take (the one place such combinations are refused)."""
        if self.projection == "equirect" and width != 2 * height:
            raise CameraError(f"an equirect image is 360 x 180 degrees: width must be 2 x height, got {width}x{height}")
        if self.stereo == "top-bottom":
            return width, 2 * height
        if self.stereo == "side-by-side":
            return 2 * width, height
        return width, height

    def eye_size(self, width: int, height: int) -> tuple[int, int]:
        """One eye's image in a painting of ``width x height`` (the inverse of :meth:`image_size`)."""
        if self.stereo == "top-bottom":
            return width, height // 2
        if self.stereo == "side-by-side":
            return width // 2, height
        return width, height

    def check_painting(self, width: int, height: int) -> None:
        """Raises :class:`CameraError` unless a painting of ``width x height`` holds whole eye images of a size
        this projection takes."""
        eye = self.eye_size(width, height)
        if min(eye) < 1 or self.image_size(*eye) != (width, height):
            raise CameraError(
                f"a {self.stereo} painting cannot be {width}x{height}: it holds two eye images of one size"
            )

    def moved(self, **changes) -> Camera:
        return replace(self, **changes)  # validated again, in __post_init__


def _choice_fault(camera: Camera) -> str | None:
    """What is wrong with a camera's projection, stereo or ipd (one line), None when nothing is."""
    for name in ("projection", "stereo", "eyes"):
        value, choices = getattr(camera, name), CAMERA_FIELDS[name].choices
        if value not in choices:
            return f"unknown {name} {value!r}; choose one of {', '.join(choices)}"
    ipd = camera.ipd
    if isinstance(ipd, bool) or not isinstance(ipd, numbers.Real) or not 0.0 <= ipd <= COORDINATE_LIMIT:
        return f"ipd must be a distance from 0 to {COORDINATE_LIMIT:g} scene units, got {ipd!r}"
    return None


@dataclass(frozen=True)
class CameraField:
    """One field of :class:`Camera` as declared: ``kind`` is ``"vec3"``, ``float`` or ``str``; ``required``: no
    default."""

    name: str
    kind: object
    default: Any
    help: str
    required: bool
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    choices: tuple[str, ...] = ()


def _camera_fields() -> dict[str, CameraField]:
    kinds = {"eye": "vec3", "look_at": "vec3", "up": "vec3", "projection": str, "stereo": str, "eyes": str}
    return {
        f.name: CameraField(
            f.name,
            kinds.get(f.name, float),
            None if f.default is MISSING else f.default,
            required=f.default is MISSING,
            **f.metadata,
        )
        for f in fields(Camera)
    }


CAMERA_FIELDS: dict[str, CameraField] = _camera_fields()
"""Every field of :class:`Camera`, in order: name -> its declaration."""


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


def eye_pixels(
    camera: Camera, region: Region, i: np.ndarray, j: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where pixels ``(i, j)`` of the painting (absolute, (n,) int64) lie in their eye's image: ``side`` (n,)
    int64 (-1 left, 1 right, 0 mono) and the eye image's ``(i, j)``."""
    width, height = camera.eye_size(region.full_width, region.full_height)
    side = np.zeros(len(i), np.int64)
    if camera.stereo == "top-bottom":
        side = np.where(j < height, -1, 1)
    elif camera.stereo == "side-by-side":
        side = np.where(i < width, -1, 1)
    return side, i % width, j % height


def directions_at(camera: Camera, region: Region, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
    """The forward map at continuous points ``(x, y)`` of an eye's image (pixel ``(i, j)`` spans ``[i, i + 1) x
    [j, j + 1)``; (n,) float64): ``d`` (n, 3), the target's offset from the eye (``P_p = eye_ij + d``), and the
    local frame ``r, u, f`` there (each (n, 3)); all float64."""
    width, height = camera.eye_size(region.full_width, region.full_height)
    r, u, f = camera.basis()
    s, t = (x / width)[:, None], (y / height)[:, None]
    if camera.projection == "equirect":
        phi = (2.0 * s - 1.0) * math.pi
        theta = (1.0 - 2.0 * t) * math.pi / 2.0
        d = np.cos(theta) * np.sin(phi) * r + np.sin(theta) * u + np.cos(theta) * np.cos(phi) * f
        r_ij = np.cos(phi) * r - np.sin(phi) * f
        return d, r_ij, np.cross(r_ij, d), d
    tan_half = camera.half_height()
    d = f + (2.0 * s - 1.0) * (width / height) * tan_half * r + (1.0 - 2.0 * t) * tan_half * u
    n = len(x)
    return d, *(np.broadcast_to(v, (n, 3)) for v in (r, u, f))


def pixel_frames(camera: Camera, region: Region, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, ...]:
    """Each pixel's own camera before displacement: its eye ``eye_ij`` and local frame ``r_ij, u_ij, f_ij`` (at
    its centre), for pixels ``(i, j)`` of the painting ((n,) int64): four (n, 3) float64."""
    side, ei, ej = eye_pixels(camera, region, i, j)
    _, r_ij, u_ij, f_ij = directions_at(camera, region, ei + 0.5, ej + 0.5)
    eyes = np.asarray(camera.eye) + (0.5 * camera.ipd * side)[:, None] * r_ij
    return eyes, r_ij, u_ij, f_ij


def sample_targets(
    camera: Camera, region: Region, i: np.ndarray, j: np.ndarray, xi: np.ndarray, eta: np.ndarray
) -> np.ndarray:
    """``P_p`` of every sample: pixels ``(i, j)`` of the painting ((n,) int64) at sub-pixel offsets ``xi, eta``
    ((n, spp) float64), (n*spp, 3) float64, sample k of pixel m in row m * spp + k."""
    side, ei, ej = eye_pixels(camera, region, i, j)
    eyes, *_ = pixel_frames(camera, region, i, j)
    d, *_ = directions_at(camera, region, (ei[:, None] + xi).ravel(), (ej[:, None] + eta).ravel())
    return np.repeat(eyes, xi.shape[1], axis=0) + d


def project(
    camera: Camera, region: Region, side: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inverse map: where directions ``d`` ((n, 3) float64) from the eye on ``side`` ((n,) int64) cross
    that eye's image, as continuous pixel coordinates of the painting with centres on the integers, and
    ``ok`` (n,) bool: False where a direction has no place there (behind a perspective camera, zero or not
    finite). Where not ok, ``x, y`` are 0."""
    width, height = camera.eye_size(region.full_width, region.full_height)
    r, u, f = camera.basis()
    with np.errstate(all="ignore"):  # non-finite input: refused below
        dr, du, df = d @ r, d @ u, d @ f
        if camera.projection == "equirect":
            length = np.sqrt(dr * dr + du * du + df * df)
            x = (np.arctan2(dr, df) / (2.0 * math.pi) + 0.5) * width - 0.5
            y = (0.5 - np.arcsin(np.clip(du / length, -1.0, 1.0)) / math.pi) * height - 0.5
            ok = length > 0.0
        else:
            tan_half = camera.half_height()
            x = (dr / df / (tan_half * width / height) + 1.0) * 0.5 * width - 0.5
            y = (1.0 - du / df / tan_half) * 0.5 * height - 0.5
            ok = df > 0.0
    ok &= np.isfinite(x) & np.isfinite(y)
    right = side > 0
    x = np.where(right & (camera.stereo == "side-by-side"), x + width, x)
    y = np.where(right & (camera.stereo == "top-bottom"), y + height, y)
    return np.where(ok, x, 0.0), np.where(ok, y, 0.0), ok
