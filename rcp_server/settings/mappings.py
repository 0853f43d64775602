"""Displacement mappings: what ``I_{n-1}`` says about where each pixel's camera moves next.

A mapping turns the previous iteration's per-pixel data into a unitless world-space field ``D``
(n, 3); the painting scales it into ``V_p = lambda_p * p * D_target`` (``p`` the pixel pitch, so
``lambda_p`` counts pixels) and ``V_e = lambda_e * D_eye`` (scene units). Each mapping declares the
channels it reads so that the renderer records only those.

Register your own ``W`` with :func:`register_mapping`::

    @register_mapping("swirl", reads={"color"})
    def swirl(data: MappingInput) -> np.ndarray:
        return np.cross(data.forward, data.color_field())
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..engine.kernels import FIELD_COLOR, FIELD_DEPTH, FIELD_GIVEN, FIELD_NORMAL
from ..engine.paintstate import CHANNELS
from ..util.sampling import STREAM_OBJECT, uniform


@dataclass(frozen=True)
class MappingInput:
    """Per-pixel data of ``I_{n-1}`` for n pixels, plus each pixel's local frame.

    color : (n, 3) float32 displayed color in [0, 1];  depth : (n,) float32 view depth (z_max on a miss)
    normal : (n, 3) float32 world normal (0 on a miss);  direction : (n, 3) float32 previous ray direction
    right, up, forward : (n, 3) float64, each pixel's ``r_ij, u_ij, f_ij`` (camera.py: the camera's own basis
    in every row on an image plane);  z0 : focus depth;  i, j : (n,) pixel column and row
    geometric, object, material, albedo, uv, position : the other channels (``paintstate.PaintState``)
    A channel the mapping did not declare is None.
    """

    color: np.ndarray
    depth: np.ndarray | None
    normal: np.ndarray | None
    direction: np.ndarray | None
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    z0: float
    i: np.ndarray
    j: np.ndarray
    geometric: np.ndarray | None = None
    object: np.ndarray | None = None
    material: np.ndarray | None = None
    albedo: np.ndarray | None = None
    uv: np.ndarray | None = None
    position: np.ndarray | None = None

    @classmethod
    def of(cls, state, frames, z0: float, i: np.ndarray, j: np.ndarray) -> MappingInput:
        """The input of every pixel of ``state`` (a ``PaintState``), each seen in its own frame: ``frames`` is
        ``(r_ij, u_ij, f_ij)``, each (n, 3) (``camera.pixel_frames``)."""
        r, u, f = frames
        return cls(z0=z0, i=i, j=j, right=r, up=u, forward=f, **{name: getattr(state, name) for name in CHANNELS})

    def rows(self, pick: np.ndarray) -> MappingInput:
        """The input of the pixels ``pick`` (an index array) only."""
        per_pixel: dict[str, Any] = {
            name: None if (a := getattr(self, name)) is None else a[pick]
            for name in (*CHANNELS, "i", "j", "right", "up", "forward")
        }
        return replace(self, **per_pixel)

    def color_field(self) -> np.ndarray:
        """``(2R-1) r + (2G-1) u + (2B-1) f`` per pixel: (n, 3) float32."""
        c = 2.0 * self.color.astype(np.float64) - 1.0
        return (c[:, :1] * self.right + c[:, 1:2] * self.up + c[:, 2:] * self.forward).astype(np.float32)


@dataclass(frozen=True)
class Mapping:
    name: str
    reads: frozenset[str]
    field: Callable[[MappingInput], np.ndarray]
    description: str = ""
    fused: int = FIELD_GIVEN  # which kernel branch computes this field; a custom W runs in numpy


MAPPINGS: dict[str, Mapping] = {}


def register_mapping(
    name: str, reads, field: Callable[[MappingInput], np.ndarray] | None = None, *, fused: int = FIELD_GIVEN
):
    """Register ``field`` (or decorate it) as mapping ``name`` reading the channels ``reads``.

    ``fused`` is for the built-in mappings only: the branch of ``kernels.cast_rays`` that computes the
    same field without leaving the kernel (``field`` stays its reference).
    """
    reads = frozenset(reads) | {"color"}  # color is always recorded: it is the image itself
    unknown = reads - set(CHANNELS)
    if unknown:
        raise ValueError(f"mapping {name!r} reads unknown channels {sorted(unknown)}; known: {sorted(CHANNELS)}")

    def register(fn):
        doc = (fn.__doc__ or "").strip().splitlines()
        MAPPINGS[name] = Mapping(name, reads, fn, doc[0] if doc else "", fused)
        return fn

    return register(field) if field is not None else register


def unregister_mapping(name: str) -> None:
    """Forget mapping ``name``, one that :func:`register_mapping` added for a while (the built-ins stay)."""
    if name in BUILT_IN:
        raise ValueError(f"mapping {name!r} is built in")
    del MAPPINGS[get_mapping(name).name]


def get_mapping(name: str) -> Mapping:
    try:
        return MAPPINGS[name]
    except KeyError:
        raise ValueError(f"unknown mapping {name!r}; valid mappings: {', '.join(sorted(MAPPINGS))}") from None


@register_mapping("color", reads={"color"}, fused=FIELD_COLOR)
def color_mapping(data: MappingInput) -> np.ndarray:
    """R moves right, G moves up, B along the view; mid-grey does not move (paper section 3)."""
    return data.color_field()


@register_mapping("depth", reads={"color", "depth"}, fused=FIELD_DEPTH)
def depth_mapping(data: MappingInput) -> np.ndarray:
    """The color field times |z - z0|: sharp at the focus depth, smudged away from it (section 4)."""
    assert data.depth is not None  # recorded: the mapping reads it
    return data.color_field() * np.abs(data.depth - np.float32(data.z0))[:, None]


@register_mapping("normal", reads={"normal", "direction"}, fused=FIELD_NORMAL)
def normal_mapping(data: MappingInput) -> np.ndarray:
    """C x N, the previous ray direction across the world normal: smudges along surfaces (section 5)."""
    assert data.direction is not None and data.normal is not None  # recorded: the mapping reads them
    return np.cross(data.direction, data.normal)


@register_mapping("cubist", reads={"object"})
def cubist_mapping(data: MappingInput) -> np.ndarray:
    """Each object its own viewpoint: a seeded direction across the view per object, none on a miss (the
    paper's cubist rendering, as an eye mapping: every object is seen from an eye of its own)."""
    assert data.object is not None  # recorded: the mapping reads it
    index = data.object.astype(np.int64)
    angle = 2.0 * np.pi * uniform(0, STREAM_OBJECT, np.maximum(index, 0))
    sideways = np.cos(angle)[:, None] * data.right + np.sin(angle)[:, None] * data.up
    return np.where((index >= 0)[:, None], sideways, 0.0).astype(np.float32)


BUILT_IN = tuple(MAPPINGS)  # the mappings every server knows; register_mapping adds more for Python callers
