"""Rays through cut-outs: a hit on a texel whose alpha is below its material's cutoff (glTF's ``MASK``,
``BLEND`` as a mask at one half, OBJ's ``map_d``) is not a hit; the ray goes on from just past it.

:func:`pass_masked` is the one place this happens; the traced method calls it wherever it intersects
(every ray of the exact path, the ``fast`` path's hits, the visible-surface pass), and only for a scene
that has such texels (``Geometry.masked``): the others pay nothing.
"""

from __future__ import annotations

import numpy as np

from . import kernels
from .camera import RAY_DTYPE
from .scene import Geometry
from .tracer import Hits, Tracer

MAX_LAYERS = 16  # cut-outs one ray passes through at most; behind more (a dense tree's leaves) it stops
# at the last (a bound on the work, not a visible limit: 16 layers of leaves are opaque anyway)


def surfaces(geometry: Geometry) -> kernels.Surfaces:
    return kernels.Surfaces(**{name: getattr(geometry, name) for name in kernels.Surfaces._fields})


def pass_masked(
    tracer: Tracer, geometry: Geometry, origins: np.ndarray, directions: np.ndarray, rays: np.ndarray, hits: Hits
) -> None:
    """Re-casts the listed ``rays`` whose hit is a masked texel from just past that hit, until none is
    (at most MAX_LAYERS times), writing their new hits into ``hits`` (distance and barycentrics placed
    from the ray's own origin, as ``kernels.place_hits`` places every hit).

    origins, directions : (n, 3) float32;  rays : (m,) int64 indices into them and into ``hits``
    """
    bundle = surfaces(geometry)
    # past the hit by a step relative to the distance, and at least a millionth of the scene's size
    floor = 1e-6 * max(float(np.linalg.norm(geometry.bounds[1] - geometry.bounds[0])), 1e-9)
    todo = np.ascontiguousarray(rays, dtype=np.int64)
    out = np.empty(len(todo), np.int64)
    for _ in range(MAX_LAYERS):
        count = kernels.masked_rays(rays=todo, hits=hits, surfaces=bundle, out=out)
        if count == 0:
            return
        todo = out[:count].copy()
        t = hits.t[todo].astype(np.float64)
        step = t + np.maximum(t * 1e-5, floor)
        start = (origins[todo] + step[:, None] * directions[todo]).astype(RAY_DTYPE)
        found = tracer.intersect(start, np.ascontiguousarray(directions[todo]))
        hits.face[todo] = found.face
        kernels.place_hits(origins=origins, directions=directions, rays=todo, triangles=geometry.triangles, hits=hits)
