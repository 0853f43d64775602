"""What every tile of one painting shares: the scene at its time as the kernels take it, looked up once."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera.camera import Camera
from ..engine import kernels
from ..engine.kernels.embree import Embree, Tracer
from ..scene.scene import Geometry, Scene
from ..settings.params import PaintParams
from . import screen
from .alphamask import step_floor
from .fields import Looks
from .outlines import ink


@dataclass(frozen=True)
class Frame:
    """What every tile of one painting shares: the scene at its time as the kernels take it, looked up once."""

    trace: kernels.Trace
    shading: kernels.Shading
    tracer: Tracer | None  # held while the painting lives: ``trace`` has only its native handle
    looks: Looks  # the settings per object and material, as the scene's indices select them

    @classmethod
    def of(
        cls,
        scene: Scene,
        time: float,
        camera: Camera,
        params: PaintParams,
        width: int = 1,
        height: int = 1,
        *,
        threads: int = 1,
        whole: bool = True,
    ) -> Frame:
        """The frame of a ``width x height`` painting (its size: where outlines are drawn), its screen cells
        built on ``threads`` threads (the painting's own, idle meanwhile). ``whole``: the painting paints the
        whole image; a band of a larger one (a print's) builds no cells, whose bytes grow with the whole image
        where a print's memory must not."""
        geometry, tracer = scene.geometry(time)
        light = scene.light
        reads = params.reads()
        z_max = params.z_max if params.z_max is not None else scene.depth_of_miss(np.asarray(camera.eye), time)
        shading = kernels.Shading(
            surfaces=kernels.Surfaces(**{name: getattr(geometry, name) for name in kernels.Surfaces._fields}),
            environment=scene.environment.image,
            light_dir=np.asarray(light.direction if light else (0.0, -1.0, 0.0), np.float64),
            ambient=float(light.ambient if light else 1.0),
            lit=light is not None,
            z_max=float(z_max),
            records=kernels.records(reads),
            materials=materials(geometry, ink(scene, time, camera, width, height)),
        )
        embree = tracer.embree if tracer is not None else Embree(0, 0, 0)
        cells = (
            screen.cells(camera, params, width, height, geometry.triangles, threads)
            if tracer and whole
            else kernels.NO_SCREEN
        )
        trace = kernels.Trace(embree, geometry.triangles, geometry.masked, step_floor(geometry), cells)
        return cls(trace, shading, tracer, Looks.of(params, geometry.object_names, geometry.material_names))


def materials(geometry: Geometry, ink: kernels.Ink) -> kernels.Materials | None:
    """What shading reads of ``geometry``'s materials beyond plain, with ``ink``; None where it has none (the
    plain one is the tables' first row)."""
    if len(geometry.material_unlit) == 1:
        return None
    fields = kernels.Materials._fields[:-1]
    return kernels.Materials(**{name: getattr(geometry, name) for name in fields}, ink=ink)
