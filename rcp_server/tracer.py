"""The only module that talks to Embree (through embreex): it owns the native scene and casts rays."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from .camera import RAY_DTYPE


class Hits(NamedTuple):
    """Closest hits of n rays (a named tuple: ``kernels.shade`` takes it as it is).

    face : (n,) int32, -1 on a miss;  t : (n,) float32 distance along the (unit) direction, meaningless on
    a miss;  b1, b2 : (n,) float32 barycentric weights of the face's second and third corners
    """

    face: np.ndarray
    t: np.ndarray
    b1: np.ndarray
    b2: np.ndarray

    @classmethod
    def misses(cls, n: int) -> Hits:
        zeros = np.zeros(n, np.float32)
        return cls(np.full(n, -1, np.int32), np.full(n, np.inf, np.float32), zeros, zeros.copy())


class Tracer:
    """An Embree BVH over one triangle soup (F, 3, 3) float32; safe to query from several threads."""

    def __init__(self, triangles: np.ndarray):
        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, np.ascontiguousarray(triangles, dtype=RAY_DTYPE))
        # commit now, once, rather than lazily inside the first (possibly concurrent) query
        self._scene.run(np.zeros((1, 3), RAY_DTYPE), np.ones((1, 3), RAY_DTYPE), query="DISTANCE")

    def intersect(self, origins: np.ndarray, directions: np.ndarray, checked: bool = False) -> Hits:
        """Closest hit of each ray. origins, directions : (n, 3) float32, directions unit length.

        Rays with a non-finite component are not sent to Embree; they miss. ``checked=True`` says the
        caller already knows every ray is finite (cast_rays counts them), which skips the mask.
        """
        if checked:
            return self._intersect(origins, directions)
        valid = np.isfinite(origins).all(axis=1) & np.isfinite(directions).all(axis=1)
        if valid.all():
            return self._intersect(origins, directions)
        hits = Hits.misses(len(origins))
        if valid.any():
            sub = self._intersect(np.ascontiguousarray(origins[valid]), np.ascontiguousarray(directions[valid]))
            for name in Hits._fields:
                getattr(hits, name)[valid] = getattr(sub, name)
        return hits

    def bare_query(self, origins: np.ndarray, directions: np.ndarray) -> None:
        """Embree's own closest-hit query and nothing else (no validity mask, no wrapping of its answer):
        what ``rcp bench speed`` compares a painting's iteration with. origins, directions : (n, 3)
        float32, finite, directions unit length."""
        self._scene.run(origins, directions, output=1)

    def _intersect(self, origins: np.ndarray, directions: np.ndarray) -> Hits:
        out = self._scene.run(origins, directions, output=1)
        return Hits(out["primID"], out["tfar"], out["u"], out["v"])
