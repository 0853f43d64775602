"""PaintParams refuses what cannot be painted, with a message naming the setting; the same painting at another scale."""

import pytest

from rcp_server.settings.mappings import BUILT_IN, MAPPINGS
from rcp_server.settings.params import PaintParams


def test_paint_params_validation():
    with pytest.raises(ValueError) as info:
        PaintParams(mapping="nope")
    assert all(name in str(info.value) for name in BUILT_IN)
    with pytest.raises(ValueError):
        PaintParams(eye_mapping="nope")
    for bad in (
        {"iterations": 0},
        {"spp": 0},
        {"lambda_p": float("nan")},
        {"lambda_e": float("inf")},
        {"z0": float("nan")},
        {"noise": -0.1},
        {"z_max": float("inf")},
    ):
        with pytest.raises(ValueError):
            PaintParams(**bad)
    with pytest.raises(ValueError, match="smudge"):
        PaintParams.from_dict({"smudge": 1})
    assert PaintParams.from_dict({"mapping": "depth", "iterations": 2}) == PaintParams(mapping="depth", iterations=2)
    assert PaintParams().iterations == 6 and "color" in MAPPINGS


def test_paint_params_method_and_edge_validation():
    assert PaintParams().method == "raytrace" and PaintParams().edge == "mirror"
    with pytest.raises(ValueError, match="raytrace, image"):
        PaintParams(method="raster")
    with pytest.raises(ValueError, match="clamp, wrap, mirror"):
        PaintParams(method="image", edge="repeat")
    with pytest.raises(ValueError, match="cannot represent eye displacement.*raytrace"):
        PaintParams(method="image", lambda_e=0.1)
    assert PaintParams.from_dict({"method": "image", "edge": "wrap"}) == PaintParams(method="image", edge="wrap")


def test_a_painting_at_another_scale_keeps_its_smudges_as_long_in_the_picture():
    params = PaintParams(lambda_p=8.0, lambda_e=0.3, objects={"tree": {"lambda_p": 2.0, "mapping": "normal"}})
    half = params.at_scale(0.5)
    assert half.lambda_p == 4.0 and half.lambda_e == 0.3  # pixels scale, scene units do not
    assert half.non_defaults()["objects"] == {"tree": {"lambda_p": 1.0, "mapping": "normal"}}
    assert params.at_scale(1.0) is params
