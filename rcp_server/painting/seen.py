"""What the pixel centres of a view see: the hits of the plain render's rays at one sample, traced once for
outlines (``outlines.ink``), for where a stereo pair's eyes see the same point (``stereo.py``), and for picking
(``picking.py``)."""

from __future__ import annotations

from ..camera.camera import Camera, Region
from ..engine import kernels
from ..engine.kernels.embree import Hits, intersect_rays
from ..engine.paintstate import PaintState
from ..scene.scene import Scene
from ..settings.params import PaintParams
from .alphamask import pass_masked
from .assign import Rays, assign_cameras, setup_tile


def visible_faces(scene: Scene, time: float, camera: Camera, region: Region, out: kernels.Seen) -> None:
    """What ``region``'s pixel centres see, into ``out`` (a bundles.Seen of the region): the hits of the
    plain render's rays at one sample, the very hits of a one-sample painting's first iteration."""
    setup = setup_tile(camera, region, PaintParams(spp=1, noise=0.0))
    rays = Rays.allocate(region.pixel_count, 1)
    assign_cameras(PaintState.canvas(region), setup, PaintParams(), 0.0, rays)
    geometry, tracer = scene.geometry(time)
    if tracer is None:
        out.face[:] = -1
        return
    hits = Hits.misses(region.pixel_count)
    intersect_rays(tracer.embree, rays.origins, rays.directions, setup.pixels, hits.face, True)
    kernels.place_hits(
        origins=rays.origins, directions=rays.directions, rays=setup.pixels, triangles=geometry.triangles, hits=hits
    )
    if geometry.masked:  # ---- alpha: cut-outs let rays through (alphamask.py) ----
        pass_masked(tracer, geometry, rays.origins, rays.directions, setup.pixels, hits)
    out.face[:] = hits.face
    out.distance[:] = hits.t
