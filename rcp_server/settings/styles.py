"""Styles: named looks of the paper, each a set of painting settings, declared once here.

A style names every setting that makes its look (:data:`LOOK`: the mappings, their strengths, the noise,
iterations and samples); the others (focus depth, miss depth, seed, method) stay the scene's. Where a style
applies, the settings stack as: the scene's, then the style's, then those given explicitly
(:func:`with_style`). The wire (``"style"`` in ``paint``), ``rcp render --style``, ``GET /api/styles`` and
the client's picker all read :data:`STYLES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from .params import PAINT_SETTINGS, PER, PaintParams, as_dict

STYLE = "style"
"""The name under which a style travels among painting settings (a ``paint`` body or message)."""

LOOK = (
    "mapping",
    "eye_mapping",
    "iterations",
    "spp",
    "lambda_p",
    "lambda_e",
    "noise",
    "surface_noise",
    "surface_scale",
    "grain",
    "hatch",
)
"""The settings every style sets: the engine's default where a style says nothing, so that no style leaks
another's look (or the scene's) into its own."""


@dataclass(frozen=True)
class Style:
    """One look: ``settings`` are painting settings by name (every one of :data:`LOOK`, perhaps more)."""

    name: str
    title: str
    description: str
    settings: dict[str, Any] = field(default_factory=dict)


def _style(name: str, title: str, description: str, **settings) -> Style:
    look = {key: PAINT_SETTINGS[key].default for key in LOOK}
    PaintParams.from_dict({**look, **settings})  # a style that cannot paint fails at import, not at a caller
    return Style(name, title, description, {**look, **settings})


STYLES: dict[str, Style] = {
    style.name: style
    for style in (
        _style(
            "smudge",
            "Colour smudge",
            "paper section 3: each pixel's target moves by its own colour; extreme colours smear into their "
            "neighbours like wet paint, average ones stay put",
            mapping="color",
            lambda_p=12.0,
        ),
        _style(
            "focus",
            "Depth focus",
            "paper section 4: the colour smudge times |z - z0|, sharp at the focus depth (the scene's, or the "
            "distance to look-at), painterly before and behind it",
            mapping="depth",
            lambda_p=0.3,
            spp=2,
        ),
        _style(
            "fractured",
            "Fractured",
            "paper section 5, the first randomness: smudges along surfaces (camera direction x normal) plus a "
            "random jump that belongs to the surface point (cells a third of a unit wide), which breaks edges "
            "into shards that stay on their walls as you walk",
            mapping="normal",
            lambda_p=14.0,
            surface_noise=0.6,
            grain=0.8,
            spp=4,
        ),
        _style(
            "cross-hatching",
            "Cross-hatching",
            "paper section 5, the other randomness: long smudges along surfaces over ten iterations, their length "
            "scaled by a noise of the surface point that is constant along the smudge and varies across it, so "
            "outlines and roofs turn into strokes drawn in lines that follow each surface",
            mapping="normal",
            lambda_p=30.0,
            surface_scale=1.0,
            surface_noise=0.2,
            hatch=True,
            grain=0.25,
            iterations=10,
            spp=2,
        ),
        _style(
            "layered",
            "Layered",
            "paper section 5, looped: the normal smudge run for 16 iterations with long displacements, which "
            "stacks silhouettes into layered outlines",
            mapping="normal",
            lambda_p=30.0,
            iterations=16,
            spp=2,
        ),
    )
}
"""Every style, by name, in the order the client lists them."""


def get_style(name: str) -> Style:
    """The style called ``name``; ``ValueError`` (one line listing the styles) for any other name."""
    try:
        return STYLES[name]
    except KeyError:
        raise ValueError(f"unknown style {name!r}; styles: {', '.join(STYLES)}") from None


def with_style(base: PaintParams, settings: Mapping[str, Any]) -> PaintParams:
    """``base`` (a scene's painting) with the style that ``settings`` names (under :data:`STYLE`, if any),
    then the other ``settings`` (name -> value), in their place: explicit settings beat the style's. Settings
    per object and per material (``objects``, ``materials``: name -> settings) merge into the base's, name by
    name and setting by setting."""
    given = dict(settings)
    name = given.pop(STYLE, None)
    style = {} if name is None else get_style(name).settings
    for per in PER:
        if per in given:
            merged = as_dict(getattr(base, per))
            for key, values in dict(given[per]).items():
                merged[key] = {**merged.get(key, {}), **(values if isinstance(values, Mapping) else {})}
                if not isinstance(values, Mapping):
                    raise ValueError(f"{per}.{key}: give a table of settings, got {values!r}")
            given[per] = merged
    return replace(base, **{**style, **given})
