"""Which paintings the screen cells answer (``kernels.screencells``, ``kernels.visibility``): perspective
cameras whose eyes stay put (``lambda_e`` 0), mono or stereo, each eye its own cells. Panoramas and moving
eyes go to Embree, and so do the paintings the cells would not pay for (``RCP_SCREEN_CELLS``,
``screencells.MODES``: ``auto`` by default): the pictures are the same either way.

The cells of the last few eyes are kept (:data:`KEPT`): the paintings of one view (a walk's frame at rest,
then its full painting and its samples) build them once.
"""

from __future__ import annotations

import threading

import numpy as np

from ..camera.camera import Camera
from ..engine import kernels
from ..engine.kernels import screencells
from ..settings.params import PaintParams

KEPT = 4  # the cells kept, the most recently used last
_kept: list[tuple[tuple, np.ndarray, kernels.Screen]] = []
_lock = threading.Lock()


def forget() -> None:
    """Drop the cells kept (``rcp bench speed`` times a build of its own)."""
    with _lock:
        _kept.clear()


def cells(
    camera: Camera,
    params: PaintParams,
    width: int,
    height: int,
    triangles: np.ndarray,
    threads: int = 1,
    mode: str | None = None,
) -> kernels.Screen:
    """The screen cells of a ``width x height`` painting of ``triangles`` (F, 3, 3) float32 by ``camera``, or
    ``kernels.NO_SCREEN`` where they do not apply; built on ``threads`` threads. ``mode``: one of
    ``screencells.MODES`` instead of ``RCP_SCREEN_CELLS``'s (the warm-up builds them whatever they pay)."""
    looks = params.looks()
    rays = width * height * params.spp * params.iterations
    chosen = mode or screencells.mode()
    if (
        not screencells.pays(rays, len(triangles), chosen)
        or camera.projection != "perspective"
        or len(triangles) == 0
        or any(look.lambda_e != 0.0 for look in looks)
    ):
        return kernels.NO_SCREEN
    eye_width, eye_height = camera.eye_size(width, height)
    basis = np.stack(camera.basis())
    eye = np.asarray(camera.eye, np.float64)
    half_ipd = 0.5 * camera.ipd if camera.stereo != "mono" else 0.0
    # as cast_rays places each eye: eye + side * half_ipd * r, in float64, stored float32
    eyes = np.array([eye + side * half_ipd * basis[0] for side in camera.sides], np.float64).astype(np.float32)
    reach = max(abs(look.lambda_p) for look in looks)
    noise = max(look.noise for look in looks)
    guard = screencells.guard_pixels(reach, noise, eye_width, eye_height)
    key = (eyes.tobytes(), basis.tobytes(), camera.half_height(), eye_width, eye_height, guard, triangles.shape, chosen)
    with _lock:
        for at, (known, faces, built) in enumerate(_kept):
            if known == key and faces is triangles:
                _kept.append(_kept.pop(at))
                return built
    built = screencells.build(triangles, eyes, basis, camera.half_height(), eye_width, eye_height, guard, threads)
    if chosen == "auto" and built.on and not screencells.answers(built):
        built = kernels.NO_SCREEN  # kept as such: the paintings of this view do not build them again
    with _lock:
        _kept.append((key, triangles, built))
        del _kept[:-KEPT]
    return built
