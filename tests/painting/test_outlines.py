"""Outlines: ink where the object, the normal or the depth jumps, a shading result the painting smudges."""

import numpy as np
from helpers.scenes import CAMERA, H, W, inked_scene

from rcp_server.painting.loop import paint
from rcp_server.settings.params import PaintParams


def test_ink_darkens_exactly_the_inked_material_where_the_view_jumps():
    plain = paint(inked_scene(0.0), CAMERA, W, H, PaintParams(iterations=1)).image
    inked = paint(inked_scene(1.0), CAMERA, W, H, PaintParams(iterations=1)).image
    shows = paint(inked_scene(0.0), CAMERA, W, H, PaintParams(iterations=1, objects={"box": {}})).state.object
    box = (shows == 0).reshape(H, W)
    dark = (inked < plain - 1e-6).any(axis=2)
    assert dark.any() and not (dark & ~box).any()  # only the inked material, never the wall
    np.testing.assert_array_equal(inked[dark], 0.0)  # ink 1: black
    np.testing.assert_array_equal(inked[~dark], plain[~dark])
    # where: along the box's silhouette and the crease between its two faces, not across its faces
    inner = box & np.roll(box, 1, 0) & np.roll(box, -1, 0) & np.roll(box, 1, 1) & np.roll(box, -1, 1)
    rim = box & ~inner
    assert dark[rim].mean() > 0.8
    crease = dark & inner  # the vertical fold between the faces: one or two columns of dark
    columns = np.flatnonzero(crease.any(axis=0))
    assert 1 <= len(columns) <= 2 and crease[:, columns].sum() >= inner[:, columns].sum() * 0.8


def test_the_painting_smudges_the_ink():
    params = PaintParams(mapping="color", lambda_p=10.0, iterations=5)
    with_ink = paint(inked_scene(1.0), CAMERA, W, H, params, keep_iterations=True).iterations
    without = paint(inked_scene(0.0), CAMERA, W, H, params).image
    first_dark = (with_ink[0] < 0.02).all(axis=2)
    last_dark = (with_ink[-1] < 0.02).all(axis=2)
    assert (last_dark & ~first_dark).any()  # ink moved where the plain render had none
    assert not np.array_equal(with_ink[-1], without)
