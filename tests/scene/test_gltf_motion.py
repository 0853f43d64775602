"""Cameras animated in a glTF (as Blender's exporter writes them) become camera paths: every frame's camera is
the animation's at that time; animations too long, too dense or not finite are refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.gltf import EYES, FOVS, PARENT, PARENT_TURN, animated_camera, expected_camera
from PIL import Image
from scipy.spatial.transform import Rotation

from rcp_server.cli import main
from rcp_server.media.camerapath import PathError, motion_path
from rcp_server.painting.loop import paint
from rcp_server.scene.scenefile import SceneError, load_scene, mesh_scene


def written(tmp_path, channels=None):
    path = tmp_path / "shot.glb"
    path.write_bytes(animated_camera(channels).glb())
    return path


def test_every_frame_of_the_path_is_the_animations_camera_at_its_time(tmp_path):
    scene = load_scene(str(written(tmp_path)))
    assert list(scene.motions) == ["Shot"]  # the still camera has no motion
    path = motion_path("camera:Shot", scene.motions, 10, 2.0)
    frames = list(path.frames())
    assert len(frames) == 26 and frames[-1].t == pytest.approx(2.5)
    t = np.array([f.t for f in frames])
    eye, forward, up, fov = expected_camera(t)
    cameras = [f.camera for f in frames]
    np.testing.assert_allclose([c.eye for c in cameras], eye, atol=1e-6)
    np.testing.assert_allclose([c.basis()[2] for c in cameras], forward, atol=1e-6)
    np.testing.assert_allclose([c.basis()[1] for c in cameras], up, atol=1e-6)
    np.testing.assert_allclose([c.fov for c in cameras], fov, atol=1e-6)
    np.testing.assert_allclose([f.scene_time for f in frames], t)
    # the motion itself between frames too (what any fps samples)
    between = np.linspace(-0.5, 3.0, 71)
    got = scene.motions["Shot"].at(between)
    for g, e in zip(got, expected_camera(between), strict=True):
        np.testing.assert_allclose(g, e, atol=1e-6)


def test_rcp_render_paints_the_animated_camera_by_name(tmp_path):
    model = written(tmp_path)
    out = tmp_path / "frames"
    args = ["-q", "render", str(model), "--path", "camera:Shot", "--fps", "2", "--width", "32", "--height", "24"]
    assert main([*args, "--out", f"{out}/"]) == 0
    frames = sorted(out.glob("frame_*.png"))
    assert len(frames) == 6
    scene = mesh_scene(model)
    path = motion_path(
        "camera:Shot", scene.motions, 2, float(np.linalg.norm(np.subtract(scene.camera.look_at, scene.camera.eye)))
    )
    last = list(path.frames())[-1]
    expected = paint(scene, last.camera, 32, 24, scene.paint, time=last.scene_time).image
    got = np.asarray(Image.open(frames[-1]).convert("RGB")).astype(float) / 255
    assert np.abs(got - expected).max() <= 1 / 255 + 1e-6
    assert main([*args, "--path", "camera:Nope", "--out", f"{out}/"]) == 2


def test_a_cubic_spline_and_a_step_are_read_as_gltf_defines_them(tmp_path):
    b_eyes = [[0, 0, 5], [2, 0, 5]]
    tangents = [[0, 0, 0], [0, 4, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, -4, 0]]  # in, value, out per key
    cubic = [tangents[0], b_eyes[0], [0, 4, 0], [0, 0, 0], b_eyes[1], [0, 0, 0]]
    channels = [
        (2, "translation", [0.0, 2.0], cubic, "CUBICSPLINE"),
        (("camera", 1), "yfov", [0.0, 1.0], FOVS[:2], "STEP"),
    ]
    scene = load_scene(str(written(tmp_path, channels)))
    motion = scene.motions["Shot"]
    eye, _, _, fov = motion.at([1.0, 0.5, 1.0])
    # Hermite at s = 1/2 with span 2: (a + b) / 2 + 2 / 8 * (out_a - in_b) = (1, 1, 5) in the parent's space
    expected = Rotation.from_quat(PARENT_TURN).apply([1.0, 2 / 8 * 4, 5.0]) + PARENT
    np.testing.assert_allclose(eye[0], expected, atol=1e-6)
    np.testing.assert_allclose(fov, np.degrees([FOVS[1], FOVS[0], FOVS[1]]), atol=1e-5)


@pytest.mark.parametrize(
    ("times", "values", "said"),
    [
        ([0.0, 1000.0], EYES[:2], "lasts 1000 s, more than the 400 s taken"),
        (np.arange(100_001) / 1000, np.zeros((100_001, 3)), "100,001 keys, where 1 to 100,000 are taken"),
        ([0.0, 1.0], [[0, 0, 5], [np.nan, 0, 5]], "its keys hold numbers that are not finite"),
        ([0.0, np.inf], EYES[:2], "its keys hold numbers that are not finite"),
        ([1.0, 0.5], EYES[:2], "its key times do not increase"),
    ],
)
def test_hostile_animations_are_refused_in_one_line(tmp_path, times, values, said):
    model = written(tmp_path, [(2, "translation", times, values, "LINEAR")])
    with pytest.raises(SceneError) as caught:
        load_scene(str(model))
    message = str(caught.value)
    assert "\n" not in message and "the animation of camera 'Shot': translation: " in message and said in message


def test_a_path_refuses_an_animation_it_cannot_hold(tmp_path):
    scene = load_scene(str(written(tmp_path, [(2, "translation", [0.0, 399.0], EYES[:2], "LINEAR")])))
    assert len(list(motion_path("camera:Shot", scene.motions, 24, 2.0).frames())) == 399 * 24 + 1
    with pytest.raises(PathError, match=r"^camera:Shot: 399 s at 30 fps is 11,971 frames, more than the 10,000"):
        motion_path("camera:Shot", scene.motions, 30, 2.0)
    with pytest.raises(PathError, match=r"^camera:Other: the scene has no animated camera 'Other' \(it has: 'Shot'\)"):
        motion_path("camera:Other", scene.motions, 24, 2.0)
