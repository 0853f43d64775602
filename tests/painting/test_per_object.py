"""Settings per object and per material: a pixel paints by the settings of the object (and material) it showed
in ``I_{n-1}``; ``lambda_p = 0`` on an object leaves exactly its pixels as in the plain render, in every
method, while the others move; names a scene does not have are refused in one line."""

from dataclasses import replace

import numpy as np
import pytest
from helpers.scenes import CAMERA, H, W, make_scene, sphere

from rcp_server.painting.loop import paint
from rcp_server.scene.meshes import Material
from rcp_server.settings.params import PaintParams

SMUDGE = PaintParams(mapping="color", lambda_p=12.0, iterations=5)


def _plain_and_painted(scene, params):
    plain = paint(scene, CAMERA, W, H, replace(params, iterations=1, objects=(), materials=())).image
    return plain, paint(scene, CAMERA, W, H, params).image


def _object_pixels(scene, name: str) -> np.ndarray:
    """Where the plain render shows the object ``name``: (H, W) bool."""
    probe = PaintParams(iterations=1, objects={name: {"lambda_p": 0.0}})
    state = paint(scene, CAMERA, W, H, probe).state
    index = scene.geometry()[0].object_names.index(name)
    return (state.object == index).reshape(H, W)


@pytest.mark.parametrize("how", [{}, {"method": "image"}, {"spp": 2}], ids=str)
def test_a_still_object_stays_exactly_plain_while_the_rest_moves(busy_scene, how):
    params = replace(SMUDGE, objects={"red": {"lambda_p": 0.0}}, **how)
    plain, painted = _plain_and_painted(busy_scene, params)
    red = _object_pixels(busy_scene, "red")
    assert red.mean() > 0.05
    if params.spp == 1:
        np.testing.assert_array_equal(painted[red], plain[red])
    else:  # a pixel is the red one's when its first sample saw it: those whose every sample saw it stay
        inner = red & np.roll(red, 1, 0) & np.roll(red, -1, 0) & np.roll(red, 1, 1) & np.roll(red, -1, 1)
        np.testing.assert_allclose(painted[inner], plain[inner], atol=0.02)
    moved = np.abs(painted - plain).max(axis=2) > 2 / 255
    assert moved[~red].mean() > 0.2  # without the override, the red sphere moves like the rest
    free = _plain_and_painted(busy_scene, replace(SMUDGE, **how))[1]
    assert (np.abs(free - plain).max(axis=2) > 2 / 255)[red].mean() > 0.2


def test_an_object_can_take_a_mapping_and_strength_of_its_own(busy_scene):
    """Only the green sphere's pixels smudge (by its normal mapping); the rest is the plain render."""
    params = replace(SMUDGE, lambda_p=0.0, objects={"green": {"lambda_p": 14.0, "mapping": "normal"}})
    plain, painted = _plain_and_painted(busy_scene, params)
    green = _object_pixels(busy_scene, "green")
    moved = np.abs(painted - plain).max(axis=2) > 2 / 255
    assert moved[green].mean() > 0.05
    # a pixel that never showed green casts its plain ray for ever
    assert not moved[~green].any()


def test_material_settings_and_the_objects_over_them():
    glass = Material(name="glass")
    left, right = (
        sphere((-1.1, 0.0, -4.0), 1.0, 2, (0.9, 0.2, 0.1), "left"),
        sphere((1.1, 0.0, -4.0), 1.0, 2, (0.1, 0.9, 0.2), "right"),
    )
    for obj in (left, right):
        part = replace(obj.part, material=glass)
        obj.part, obj.instances = part, [(obj.instances[0][0], part)]
    scene = make_scene([left, right])
    # the material's lambda_p 0 holds both spheres still; the right one's own setting wins over it
    params = replace(SMUDGE, materials={"glass": {"lambda_p": 0.0}}, objects={"right": {"lambda_p": 12.0}})
    plain, painted = _plain_and_painted(scene, params)
    moved = np.abs(painted - plain).max(axis=2) > 2 / 255
    lefts, rights = _object_pixels(scene, "left"), _object_pixels(scene, "right")
    assert not moved[lefts].any()
    assert moved[rights].mean() > 0.05


def test_the_image_method_paints_per_object_settings_as_the_traced_one(busy_scene):
    params = replace(SMUDGE, objects={"red": {"lambda_p": 0.0}, "green": {"mapping": "normal", "lambda_p": 14.0}})
    exact = paint(busy_scene, CAMERA, W, H, params).image
    image = paint(busy_scene, CAMERA, W, H, replace(params, method="image")).image
    red = _object_pixels(busy_scene, "red")
    np.testing.assert_array_equal(image[red], exact[red])  # both leave the still sphere as it is


def test_unknown_names_and_settings_are_refused_in_one_line(busy_scene):
    with pytest.raises(ValueError, match=r"objects: this scene has no 'figure' \(it has: 'plane', 'red'") as info:
        busy_scene.painting({"objects": {"figure": {"lambda_p": 0}}})
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match="materials: this scene has no 'stone'"):
        paint(busy_scene, CAMERA, W, H, PaintParams(materials={"stone": {"lambda_p": 0}}))
    with pytest.raises(ValueError, match="objects.red: iterations cannot vary per pixel"):
        PaintParams(objects={"red": {"iterations": 3}})
    with pytest.raises(ValueError, match="objects.red: lambda_p must be at most"):
        busy_scene.painting({"objects": {"red": {"lambda_p": 1e9}}})
    with pytest.raises(ValueError, match="eye displacement"):
        PaintParams(method="image", objects={"red": {"lambda_e": 0.1}})


def test_overrides_merge_name_by_name_over_the_scenes(busy_scene):
    scene = make_scene(busy_scene.objects)
    scene.paint = PaintParams(objects={"red": {"lambda_p": 0.0, "noise": 0.2}})
    params = scene.painting({"objects": {"red": {"noise": 0.0}, "blue": {"lambda_p": 3.0}}})
    assert params.non_defaults()["objects"] == {"red": {"lambda_p": 0.0, "noise": 0.0}, "blue": {"lambda_p": 3.0}}
