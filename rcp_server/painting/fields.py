"""A painting's displacement fields per pixel, in numpy: each pixel's own settings and both kinds of noise.

A pixel paints with the settings of the object and the material it showed in ``I_{n-1}`` (a miss: the
painting's own; ``PaintParams.overridden``): :class:`Looks` lists the distinct settings a painting may use
and which one each (object, material) pair takes. Its field is then

    ``V_p = lambda_p p (D (1 + surface_scale h) + surface_noise v + noise n)``,  ``V_e`` alike with ``lambda_e``

``D`` the mapping's field (``mappings.py``), ``n`` the screen noise (a fixed random vector per pixel, in the
camera's frame: ``assign.setup_tile``), and ``h, v`` the **surface noise** (:func:`surface_noise`): one
seeded value per cell of ``grain`` scene units of the world, so a stroke stays on its wall as the camera
moves. It is read where the pixel's first ray of the painting met the scene (the plain render's point), not
where ``I_{n-1}``'s displaced ray did: read there, each iteration's noise moved the point the next one read,
and a walk's small steps came out as flicker. With ``hatch`` it is read along the line across the smudge
only, so it is constant along the displacement and varies across it: hatch lines.

:func:`displacements` is the one full statement; ``kernels.cast_rays`` computes the common case fused (one
look, a built-in mapping, no surface noise: :meth:`Looks.fused`), checked against it in ``tests/engine``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..engine.paintstate import PaintState
from ..settings.mappings import MappingInput, get_mapping
from ..settings.params import PaintParams
from ..util.sampling import STREAM_SURFACE, uniform


@dataclass(frozen=True)
class Looks:
    """The settings a painting's pixels paint with: ``looks[0]`` the painting's own, the others its overrides;
    ``table[object + 1, material + 1]`` the look of a pixel that showed that object and material row (row 0:
    a miss) of the scene's ``Geometry``."""

    looks: tuple[PaintParams, ...]
    table: np.ndarray  # (objects + 1, material rows + 1) int64

    @classmethod
    def of(cls, params: PaintParams, object_names: list[str], material_names: list[str]) -> Looks:
        """The looks of ``params`` in a scene whose objects and material rows are called so (only the names
        the overrides give are visited: a large model has thousands of parts)."""
        looks = [params]
        table = np.zeros((len(object_names) + 1, len(material_names) + 1), np.int64)

        def look(obj: str | None, material: str | None) -> int:
            settings = params.overridden(obj, material)
            if settings not in looks:
                looks.append(settings)
            return looks.index(settings)

        materials = [(m + 1, name) for m, name in enumerate(material_names) if name in dict(params.materials)]
        for column, name in materials:
            table[1:, column] = look(None, name)  # any object made of it (row 0: a miss, which has none)
        for o, name in enumerate(object_names):
            if name in dict(params.objects):
                table[o + 1, :] = look(name, None)
                for column, material in materials:
                    table[o + 1, column] = look(name, material)
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


_OBLIQUE = np.linalg.qr(np.array([[0.8, 0.3, -0.5], [-0.2, 0.9, 0.4], [0.6, -0.3, 0.7]]))[0]
"""A fixed turn of the surface noise's cells: walls square to the world's axes ran straight across floors
and facades, one seam the width of the view."""


def surface_noise(
    seed: int, position: np.ndarray, grain: float, across: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The surface noise at world points: ``h`` (n,) and ``v`` (n, 3) float64 in [-1, 1], one seeded value per
    cell of ``grain`` scene units (the cells' walls are where a smudge breaks: shards), the same at the same
    point whatever the camera, 0 where there is no point (NaN: the sky). ``across`` (n, 3) unit vectors: read
    along them only (slabs instead of cubes), so it is constant across every plane they are normal to: with
    the smudge in that plane, hatch lines."""
    p = np.asarray(position, np.float64) @ _OBLIQUE / grain
    if across is not None:
        p = np.einsum("ij,ij->i", p, across @ _OBLIQUE)[:, None] * np.array([1.0, 0.0, 0.0])
    point = np.isfinite(p).all(axis=1, keepdims=True)  # the sky has none: no noise there
    cell = np.floor(np.where(point, p, 0.0)).astype(np.int64).astype(np.uint64)  # negatives wrap
    values = 2.0 * uniform(seed, STREAM_SURFACE, cell[:, :1], cell[:, 1:2], cell[:, 2:], np.arange(4)) - 1.0
    values = np.where(point, values, 0.0)
    return values[:, 0], values[:, 1:]


def _unit(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, length, out=np.zeros_like(v), where=length > 0)


def _field(data: MappingInput, look: PaintParams, mapping: str, points, pick, screen) -> np.ndarray:
    """``D (1 + surface_scale h) + surface_noise v + noise n`` of one look at the pixels ``pick``: (m, 3);
    ``points`` (n, 3): where each pixel reads the surface noise."""
    d = np.asarray(get_mapping(mapping).field(data), np.float64)
    if look.surface_noise or look.surface_scale:
        across = None
        if look.hatch:  # along the surface, at right angles to the smudge
            assert data.normal is not None  # recorded: PaintParams.reads asks for it
            normal = np.asarray(data.normal, np.float64)
            normal = np.where((np.linalg.norm(normal, axis=1) > 0)[:, None], normal, data.forward)
            across = _unit(np.cross(normal, d))
        h, v = surface_noise(look.seed, points[pick], look.grain, across)
        d = d * (1.0 + look.surface_scale * h)[:, None] + look.surface_noise * v
    if look.noise and screen is not None:
        d = d + look.noise * screen[pick]
    return d


def displacements(
    state: PaintState,
    data: MappingInput,
    looks: Looks,
    pitch: float,
    screen: np.ndarray | None,
    anchor: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(V_p, V_e)`` of every pixel from ``I_{n-1}``: two (n, 3) float64, scene units, each pixel with its own
    look (``looks.rows``). ``data``: the mapping input of the whole state; ``screen``: (n, 3) the screen noise,
    or None; ``anchor`` (n, 3): the world points where the surface noise is read (the painting's first
    iteration's, ``raytrace.TracedTile``), default the points ``I_{n-1}`` recorded. A non-finite displacement
    moves nothing."""
    points = anchor if anchor is not None else state.position
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
                    out[pick] = scale * _field(part, look, mapping, points, pick, screen)
    for v in (v_p, v_e):
        v[~np.isfinite(v)] = 0.0
    return v_p, v_e
