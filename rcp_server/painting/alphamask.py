"""Rays through cut-outs: a hit on a texel whose alpha is below its material's cutoff (glTF's ``MASK``,
``BLEND`` as a mask at one half, OBJ's ``map_d``) is not a hit; the ray goes on from just past it.

``kernels.pass_masked`` is the one place this happens; the traced method calls it wherever it intersects
(in a tile's iteration, every ray, decided by the visible-surface grid or by Embree; here, for the
visible-surface pass), and only for a scene that has such texels (``Geometry.masked``): the others pay
nothing.
"""

from __future__ import annotations

import numpy as np

from ..engine import kernels
from ..engine.kernels.embree import Hits, Tracer
from ..scene.scene import Geometry


def pass_masked(
    tracer: Tracer, geometry: Geometry, origins: np.ndarray, directions: np.ndarray, rays: np.ndarray, hits: Hits
) -> None:
    """Re-casts the listed ``rays`` whose hit is a masked texel from just past that hit, until none is
    (``kernels.pass_masked``), writing their new hits into ``hits``.

    origins, directions : (n, 3) float32;  rays : (m,) int64 indices into them and into ``hits``
    """
    kernels.pass_masked(
        embree=tracer.embree,
        triangles=geometry.triangles,
        surfaces=surfaces(geometry),
        origins=origins,
        directions=directions,
        rays=np.ascontiguousarray(rays, dtype=np.int64),
        hits=hits,
        floor=step_floor(geometry),
        starts=np.empty_like(origins),
        todo=np.empty(len(rays), np.int64),
        next_todo=np.empty(len(rays), np.int64),
    )


def step_floor(geometry: Geometry) -> float:
    """The least step past a masked hit: a millionth of the scene's size."""
    return 1e-6 * max(float(np.linalg.norm(geometry.bounds[1] - geometry.bounds[0])), 1e-9)


def surfaces(geometry: Geometry) -> kernels.Surfaces:
    return kernels.Surfaces(**{name: getattr(geometry, name) for name in kernels.Surfaces._fields})
