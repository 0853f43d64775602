"""What a walk frame costs on a Ray worker, measured on an actor of its own before walkers are admitted."""

from __future__ import annotations

from ..camera.camera import Camera
from ..settings.params import PaintParams
from .admission import CostMeter
from .connection import ClusterError, ray_module, worker_failure
from .pool import FIRST_FRAME_S, Pool, kill

SMALL = 8  # pixels each way of the frames that measure a frame's fixed cost
CALIBRATION_FRAMES = 3  # frames of each size measured: the cheapest counts (the others met a busy core)


def calibrate(
    pool: Pool, held, cost: CostMeter, camera: Camera, params: PaintParams, width: int, height: int
) -> tuple[float, float]:
    """Measure what a frame costs on a worker into ``cost`` (:class:`~.admission.CostMeter`), on an actor of its
    own: frames of the ``held`` scene seen from ``camera`` with ``params`` at ``width x height`` and at ``SMALL``
    pixels (the fewest CPU seconds of ``CALIBRATION_FRAMES`` each, after one that builds the scene). Returns (CPU
    seconds a frame, a ray)."""
    ray = ray_module()
    actor, warm = pool.started(held)
    try:
        ray.get(warm, timeout=FIRST_FRAME_S)

        def cpu_s(width: int, height: int) -> float:
            shot = (camera, width, height, params, 0.0, 70)
            calls = [actor.frame.remote(held, *shot, k, None) for k in range(CALIBRATION_FRAMES)]
            return min(p.cpu_s for p in ray.get(calls, timeout=FIRST_FRAME_S))

        small, large = cpu_s(SMALL, SMALL), cpu_s(width, height)
    except Exception as exc:
        raise ClusterError(f"the cost of a frame on Ray was not measured: {worker_failure(exc)}") from None
    finally:
        kill(actor)
    per_pixel = params.spp * params.iterations
    rays = width * height * per_pixel - SMALL * SMALL * per_pixel
    ray_s = max(large - small, 0.0) / max(rays, 1)
    cost.calibrated(small - SMALL * SMALL * per_pixel * ray_s, ray_s)
    assert cost.frame_s is not None
    return cost.frame_s, ray_s
