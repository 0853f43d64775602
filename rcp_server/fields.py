"""A painting's displacement fields per pixel, in numpy: each pixel's own settings and both kinds of noise.

A pixel paints with the settings of the object and the material it showed in ``I_{n-1}`` (a miss: the
painting's own; ``PaintParams.overridden``): :class:`Looks` lists the distinct settings a painting may use
and which one each (object, material) pair takes. Its field is then

    ``V_p = lambda_p p (D (1 + surface_scale h) + surface_noise v + noise n)``,  ``V_e`` alike with ``lambda_e``

``D`` the mapping's field (``mappings.py``), ``n`` the screen noise (a fixed random vector per pixel, in the
camera's frame: ``raytrace.setup_tile``), and ``h, v`` the **surface noise**: a seeded value noise of the
world point the pixel saw, ``grain`` scene units a cell, so a stroke stays on its wall as the camera moves
(:func:`surface_noise`). With ``hatch`` it is read along the line across the smudge only, so it is constant
along the displacement and varies across it: hatch lines.

:func:`displacements` is the one full statement; ``kernels.cast_rays`` computes the common case fused (one
look, a built-in mapping, no surface noise: :func:`fused`), checked against it in ``tests/engine``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mappings import MappingInput, get_mapping
from .paintstate import PaintState
from .params import PaintParams
from .sampling import STREAM_SURFACE, uniform


@dataclass(frozen=True)
class Looks:
    """The settings a painting's pixels paint with: ``looks[0]`` the painting's own, the others its overrides;
    ``table[object + 1, material + 1]`` the look of a pixel that showed that object and material row (row 0:
    a miss) of the scene's ``Geometry``."""

    looks: tuple[PaintParams, ...]
    table: np.ndarray  # (objects + 1, material rows + 1) int64

    @classmethod
    def of(cls, params: PaintParams, object_names: list[str], material_names: list[str]) -> Looks:
        """The looks of ``params`` in a scene whose objects and material rows are called so."""
        looks = [params]
        table = np.zeros((len(object_names) + 1, len(material_names) + 1), np.int64)
        if params.objects or params.materials:
            for o, obj in enumerate([None, *object_names]):
                for m, material in enumerate([None, *material_names]):
                    look = params.overridden(obj, material or None) if obj is not None else params
                    if look not in looks:
                        looks.append(look)
                    table[o, m] = looks.index(look)
        return cls(tuple(looks), table)

    @classmethod
    def single(cls, params: PaintParams) -> Looks:
        return cls((params,), np.zeros((1, 1), np.int64))

    def rows(self, state: PaintState) -> np.ndarray:
        """The look of every pixel of ``state``: (n,) int64 (the object and material it recorded)."""
        n = state.region.pixel_count
        if len(self.looks) == 1 or state.blank:
            return np.zeros(n, np.int64)
        o = np.zeros(n, np.int64) if state.object is None else state.object.astype(np.int64) + 1
        m = np.zeros(n, np.int64) if state.material is None else state.material.astype(np.int64) + 1
        return self.table[o, m]

    def fused(self) -> bool:
        """Whether ``kernels.cast_rays`` computes these fields itself: one look, its mappings built in (or
        not moving), no surface noise."""
        if len(self.looks) > 1:
            return False
        (look,) = self.looks
        eye_fused = look.lambda_e == 0.0 or get_mapping(look.eye_mapping).fused != 4
        return get_mapping(look.mapping).fused != 4 and eye_fused and not (look.surface_noise or look.surface_scale)

    @property
    def targets_move(self) -> bool:
        return any(look.lambda_p != 0.0 for look in self.looks)

    @property
    def eyes_move(self) -> bool:
        return any(look.lambda_e != 0.0 for look in self.looks)


def surface_noise(
    seed: int, position: np.ndarray, grain: float, across: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The surface noise at world points: ``h`` (n,) and ``v`` (n, 3) float64 in [-1, 1], smooth (trilinear
    between cells of ``grain`` scene units, seeded values at their corners), the same at the same point
    whatever the camera. ``across`` (n, 3) unit vectors: read only along them (and along ``position``'s
    own normal direction is not known here), so the noise is constant across every plane they are normal to.
    """
    p = np.asarray(position, np.float64) / grain
    if across is not None:
        p = np.stack([np.einsum("ij,ij->i", p, across), np.zeros(len(p)), np.zeros(len(p))], axis=1)
    p = np.where(np.isfinite(p), p, 0.0)
    cell = np.floor(p)
    f = p - cell
    w = f * f * (3.0 - 2.0 * f)  # smoothstep: no creases at the cell walls
    corner = cell.astype(np.int64)
    total = np.zeros((len(p), 4))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                key = (corner + np.array([dx, dy, dz])).astype(np.uint64)  # two's complement: negatives differ too
                values = uniform(seed, STREAM_SURFACE, key[:, :1], key[:, 1:2], key[:, 2:], np.arange(4))
                weight = (
                    (w[:, 0] if dx else 1.0 - w[:, 0])
                    * (w[:, 1] if dy else 1.0 - w[:, 1])
                    * (w[:, 2] if dz else 1.0 - w[:, 2])
                )
                total += weight[:, None] * values
    signed = 2.0 * total - 1.0
    return signed[:, 0], signed[:, 1:]


def _unit(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)


def _field(data: MappingInput, look: PaintParams, mapping: str, state: PaintState, pick, screen) -> np.ndarray:
    """``D (1 + surface_scale h) + surface_noise v + noise n`` of one look at the pixels ``pick``: (m, 3)."""
    d = np.asarray(get_mapping(mapping).field(data), np.float64)
    if look.surface_noise or look.surface_scale:
        assert state.position is not None  # recorded: PaintParams.reads asks for it
        across = None
        if look.hatch:  # along the surface, at right angles to the smudge
            assert state.normal is not None
            normal = np.asarray(state.normal[pick], np.float64)
            normal = np.where((np.linalg.norm(normal, axis=1) > 0)[:, None], normal, data.forward)
            across = _unit(np.cross(normal, d))
        h, v = surface_noise(look.seed, state.position[pick], look.grain, across)
        d = d * (1.0 + look.surface_scale * h)[:, None] + look.surface_noise * v
    if look.noise and screen is not None:
        d = d + look.noise * screen[pick]
    return d


def displacements(
    state: PaintState, data: MappingInput, looks: Looks, pitch: float, screen: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """``(V_p, V_e)`` of every pixel from ``I_{n-1}``: two (n, 3) float64, scene units, each pixel with its own
    look (``looks.rows``). ``data``: the mapping input of the whole state; ``screen``: (n, 3) the screen noise,
    or None. A non-finite displacement moves nothing."""
    n = state.region.pixel_count
    v_p, v_e = np.zeros((n, 3)), np.zeros((n, 3))
    rows = looks.rows(state)
    for row, look in enumerate(looks.looks):
        pick = slice(None) if len(looks.looks) == 1 else np.flatnonzero(rows == row)
        if len(looks.looks) > 1 and not len(pick):  # type: ignore[arg-type]  # an index array here
            continue
        part = data if isinstance(pick, slice) else data.rows(pick)
        for out, mapping, scale in ((v_p, look.mapping, look.lambda_p * pitch), (v_e, look.eye_mapping, look.lambda_e)):
            if scale != 0.0:
                with np.errstate(all="ignore"):  # non-finite input moves nothing, below
                    out[pick] = scale * _field(part, look, mapping, state, pick, screen)
    for v in (v_p, v_e):
        v[~np.isfinite(v)] = 0.0
    return v_p, v_e
