"""The painting keyed along a camera path: each setting's track, the frames painted with it, cross-fades, and
path files without it as they always were."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rcp_server import PaintParams, paint
from rcp_server.media.camerapath import PathError, load_path, parse_path
from rcp_server.painting.sequence import paint_results

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
W, H = 48, 32


def key(t, z, **more):
    return {"t": t, "eye": [0.0, 0.0, z], "look_at": [0.0, 0.0, z - 1.0], **more}


def path_of(keyframes, scene, base=None, **more):
    spec = parse_path({"keyframes": keyframes, "fps": 2, **more})
    return spec.resolve(scene.camera).with_painting(base or PaintParams(), scene.check_names)


def params_at(path, t):
    (frame,) = [f for f in path.frames() if abs(f.t - t) < 1e-9]
    return frame


def test_a_path_without_painting_loads_and_writes_as_before(busy_scene):
    source = json.loads((EXAMPLES / "walk.json").read_text())
    path = load_path(EXAMPLES / "walk.json", busy_scene.camera)
    assert path.paints == () and path.with_painting(PaintParams(lambda_p=3.0)) is path
    assert all(frame.looks == () for frame in path.frames())
    written = json.loads(path.to_json())
    assert all(set(k) <= {"t", "eye", "look_at", "up", "fov", "scene_time", "projection", "stereo", "ipd", "eyes"}
               for k in written["keyframes"])  # fmt: skip
    assert [k["eye"] for k in written["keyframes"]] == [k["eye"] for k in source["keyframes"]]


def test_each_setting_follows_its_own_keys_and_holds_beyond_them(busy_scene):
    keys = [
        key(0, 0.0),
        key(1, -0.1, paint={"lambda_p": 2.0, "iterations": 3}),
        key(2, -0.2, paint={"z0": 5.0, "objects": {"red": {"noise": 0.5}}}),
        key(3, -0.3, paint={"lambda_p": 10.0, "iterations": 5, "objects": {"red": {"noise": 1.5}}}),
        key(4, -0.4),
    ]
    path = path_of(keys, busy_scene, PaintParams(lambda_p=7.0, spp=2))
    looks = {f.t: f.looks for f in path.frames()}
    assert all(len(v) == 1 and v[0][1] == 1.0 for v in looks.values())
    at = {t: v[0][0] for t, v in looks.items()}
    # lambda_p: keyed at 1 and 3 only (two keys: a straight line), held before and after
    assert [at[t].lambda_p for t in (0, 0.5, 1, 2, 3, 4)] == pytest.approx([2, 2, 2, 6, 10, 10])
    assert at[1.5].lambda_p == pytest.approx(4.0)
    # iterations step at their keys (the film's own before the first); z0 keyed once holds everywhere
    assert [at[t].iterations for t in (0, 1, 2.5, 3, 4)] == [6, 3, 3, 5, 5]
    assert {at[t].z0 for t in at} == {5.0} and {at[t].spp for t in at} == {2}
    # a per-object setting has its track too
    assert [dict(dict(at[t].objects)["red"])["noise"] for t in (0, 2, 2.5, 3, 4)] == pytest.approx(
        [0.5, 0.5, 1.0, 1.5, 1.5]
    )


def test_a_frame_between_two_keys_is_the_still_painted_with_the_interpolated_settings(busy_scene):
    keys = [key(0, 0.0, paint={"lambda_p": 0.0, "noise": 0.0}), key(2, -0.6, paint={"lambda_p": 16.0, "noise": 0.4})]
    path = path_of(keys, busy_scene)

    def paint_frame(camera, scene_time, params, previous):
        return paint(busy_scene, camera, W, H, params, time=scene_time, previous=previous)

    frames = list(paint_results(paint_frame, path.frames(), PaintParams()))
    (camera,), _ = path.at(np.array([1.0]))
    still = paint(busy_scene, camera, W, H, PaintParams(lambda_p=8.0, noise=0.2), time=1.0).image
    np.testing.assert_array_equal(frames[2].image, still)
    plain = paint(busy_scene, path.cameras[0], W, H, PaintParams(lambda_p=0.0)).image
    np.testing.assert_array_equal(frames[0].image, plain)  # lambda_p 0 at the first key: the plain render
    assert (
        np.abs(frames[2].image - paint(busy_scene, camera, W, H, PaintParams(lambda_p=0.0), time=1.0).image).max() > 0.1
    )


def test_a_change_of_mapping_cross_fades_and_its_midpoint_is_the_blend(busy_scene):
    keys = [
        key(0, 0.0, paint={"mapping": "color", "lambda_p": 10.0}),
        key(1, -0.1),
        key(3, -0.3, paint={"style": "layered", "lambda_p": 10.0}, fade=2.0),
    ]
    path = path_of(keys, busy_scene)
    mid = params_at(path, 2.0).looks
    assert [(p.mapping, p.iterations, w) for p, w in mid] == [("color", 6, 0.5), ("normal", 16, 0.5)]
    assert [(p.mapping, w) for p, w in params_at(path, 1.0).looks] == [("color", 1.0)]  # the fade starts after
    assert [(p.mapping, w) for p, w in params_at(path, 3.0).looks] == [("normal", 1.0)]  # and ends at the key
    quarter = path_of([keys[0], {**keys[2], "t": 2.5}], busy_scene)  # 2 s fade ending at 2.5: w 0.75 at 2.0
    assert [w for _, w in params_at(quarter, 2.0).looks] == [0.25, 0.75]

    def paint_frame(camera, scene_time, params, previous):
        return paint(busy_scene, camera, W, H, params, time=scene_time, previous=previous)

    (frame,) = list(paint_results(paint_frame, [params_at(path, 2.0)], PaintParams()))
    camera = params_at(path, 2.0).camera
    before = paint(busy_scene, camera, W, H, replace(PaintParams(), lambda_p=10.0), time=2.0).image
    after = paint(busy_scene, camera, W, H, replace(mid[1][0]), time=2.0).image
    np.testing.assert_allclose(frame.image, 0.5 * before + 0.5 * after, atol=1e-6)
    assert np.abs(before - after).max() > 0.2  # two paintings that differ: the blend is neither


def test_keyed_paintings_that_cannot_paint_are_refused_in_one_line_naming_the_keyframe(busy_scene):
    base = [key(0, 0.0), key(1, -0.1)]
    cases = {
        "keyframes.1.paint: lambda_p must be at most": {"lambda_p": 1e9},
        "keyframes.1.paint: unknown style": {"style": "nope"},
        "keyframes.1.paint: objects: this scene has no 'ghost'": {"objects": {"ghost": {"lambda_p": 1.0}}},
        "keyframes.1.paint: objects.red: iterations cannot vary per pixel": {"objects": {"red": {"iterations": 2}}},
    }
    for message, paint_table in cases.items():
        with pytest.raises(PathError) as caught:
            path_of([base[0], {**base[1], "paint": paint_table}], busy_scene)
        assert str(caught.value).startswith(message) and "\n" not in str(caught.value)
    with pytest.raises(PathError, match=r"^keyframes\.1\.fade: .*at most the time since the keyframe before"):
        path_of([base[0], {**base[1], "paint": {"lambda_p": 1.0}, "fade": 1.5}], busy_scene)
    with pytest.raises(PathError, match=r"^keyframes\.1\.fade: a fade belongs to a keyframe with a paint table"):
        path_of([base[0], {**base[1], "fade": 0.5}], busy_scene)


def test_ease_slows_the_camera_into_and_out_of_its_keys(busy_scene):
    plain = [key(0, 0.0), key(2, -2.0), key(4, -4.0)]
    eased = [{**plain[0], "ease": [0, 1]}, {**plain[1], "ease": [1, 0.5]}, plain[2]]
    a, b = path_of(plain, busy_scene), path_of(eased, busy_scene)
    t = np.array([0.0, 0.05, 1.0, 1.95, 2.0, 2.05, 3.0, 4.0])
    za = np.array([c.eye[2] for c in a.at(t)[0]])
    zb = np.array([c.eye[2] for c in b.at(t)[0]])
    np.testing.assert_allclose(zb[[0, 4, 7]], [0.0, -2.0, -4.0], atol=1e-9)  # through every key at its time
    np.testing.assert_allclose(zb[2], za[2], atol=1e-9)  # a segment eased at both ends: its middle in time
    assert abs(zb[1]) < 0.1 * abs(za[1]) and abs(zb[3] + 2) < 0.1 * abs(za[3] + 2)  # at rest by its keys
    assert abs(zb[5] + 2) < abs(za[5] + 2)  # half an ease out of the second
    assert np.all(np.diff([c.eye[2] for c in b.at(np.linspace(0, 4, 81))[0]]) <= 1e-12)  # never back
    assert json.loads(b.to_json())["keyframes"][1]["ease"] == [1, 0.5]
    assert "ease" not in json.loads(a.to_json())["keyframes"][1]
    with pytest.raises(PathError, match=r"keyframes\.1\.ease"):
        path_of([plain[0], {**plain[1], "ease": [0, 2]}], busy_scene)
