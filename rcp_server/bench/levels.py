"""``rcp bench levels``: is comparing colors in quarter display levels (``kernels.REUSE_LEVELS``: the ``fast``
setting's reuse of pixels whose color settled) a smaller change to a painting than a change of seed?

Each shipped scene is painted with its own settings at 4 samples per pixel three times, all ``fast``:
colors compared bit for bit, in the reuse's levels (the convention), and bit for bit with another seed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..engine import kernels
from ..painting.loop import paint
from ..scene.scenefile import load_scene

SCENES = ("default", "sea", "sky")


def difference(a: np.ndarray, b: np.ndarray) -> str:
    """How far apart two paintings are: the share of pixels within 2/255 in every channel, and the RMS."""
    close = (np.abs(a - b).max(axis=2) <= 2 / 255 + 1e-6).mean()
    return f"{close:7.2%} within 2/255, RMS {np.sqrt(((a - b) ** 2).mean()) * 255:5.2f}/255"


def levels(width: int, height: int, scenes=SCENES) -> None:
    print(f"{width}x{height}, 4 spp, each scene's own painting settings, fast")
    convention = kernels.REUSE_LEVELS
    try:
        for name in scenes:
            scene = load_scene(name)
            params = replace(scene.paint, spp=4)
            kernels.REUSE_LEVELS = 0  # colors compared bit for bit: a pixel is kept only if exactly the same
            bits = paint(scene, scene.camera, width, height, params).image
            other_seed = paint(scene, scene.camera, width, height, replace(params, seed=params.seed + 1)).image
            kernels.REUSE_LEVELS = convention
            shown = paint(scene, scene.camera, width, height, params).image
            print(f"{name:8s} display levels against bits: {difference(shown, bits)}")
            print(f"{'':8s} another seed against bits:    {difference(other_seed, bits)}")
    finally:
        kernels.REUSE_LEVELS = convention
