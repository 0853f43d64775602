"""Camera paths: the file format's checks, the frames' times, and curves that pass through the keyframes
smoothly, without flips."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rcp_server.camera.camera import Camera
from rcp_server.media.camerapath import MAX_FRAMES, PathError, load_path, parse_path

SCENE_CAMERA = Camera((0.0, 1.0, 5.0), (0.0, 1.0, 0.0), up=(0.0, 1.0, 0.0), fov=50.0)


def key(t, eye, look_at=(0.0, 1.0, 0.0), **more):
    return {"t": t, "eye": list(eye), "look_at": list(look_at), **more}


ORBIT = [key(0, (0, 1, 5)), key(1, (5, 1, 0)), key(2.5, (0, 1, -5), fov=40), key(3, (-5, 1, 0))]


def resolve(keyframes, **more):
    return parse_path({"keyframes": keyframes, **more}).resolve(SCENE_CAMERA)


def views(path, t):
    cameras, scene_times = path.at(np.asarray(t, dtype=float))
    eye = np.array([c.eye for c in cameras])
    forward = np.array([c.basis()[2] for c in cameras])
    up = np.array([c.basis()[1] for c in cameras])
    return eye, forward, up, np.array([c.fov for c in cameras]), np.array(scene_times)


def test_frames_every_step_from_zero_to_the_last_keyframe_both_included():
    path = resolve(ORBIT, fps=24)
    frames = list(path.frames())
    assert path.frame_count == len(frames) == 73
    assert [f.index for f in frames] == list(range(73))
    np.testing.assert_allclose([f.t for f in frames], np.arange(73) / 24, atol=1e-12)
    # an end between two steps: the last frame is the last step before it
    assert resolve([key(0, (0, 1, 5)), key(1.03, (5, 1, 0))], fps=10).frame_count == 11
    # a part of the frames, as a worker asks for them
    assert [f.t for f in path.frames(70)] == [f.t for f in frames[70:]]


def test_the_curves_pass_through_every_keyframe_at_its_time():
    path = resolve(ORBIT)
    eye, forward, up, fov, scene_time = views(path, [0, 1, 2.5, 3])
    np.testing.assert_allclose(eye, [k["eye"] for k in ORBIT], atol=1e-9)
    expected = np.array([k["look_at"] for k in ORBIT]) - eye
    np.testing.assert_allclose(forward, expected / np.linalg.norm(expected, axis=1, keepdims=True), atol=1e-9)
    np.testing.assert_allclose(fov, [50, 50, 40, 40])  # the scene's, then the previous keyframe's
    np.testing.assert_allclose(scene_time, [0, 1, 2.5, 3])  # scene time defaults to t
    np.testing.assert_allclose(up[:, 1], np.ones(4) * (1 - forward[:, 1] ** 2) ** 0.5, atol=1e-9)


def test_an_orbit_keeps_its_target_on_screen_and_its_horizon_level():
    path = resolve(ORBIT, fps=30)
    cameras, _ = path.at(path.frame_times())
    for camera in cameras:
        f = camera.basis()[2]
        to_target = np.subtract((0.0, 1.0, 0.0), camera.eye)
        assert np.dot(f, to_target / np.linalg.norm(to_target)) > 1 - 1e-9
        assert abs(camera.basis()[0][1]) < 1e-9  # the right vector stays horizontal: no roll


def test_the_eye_moves_with_a_velocity_continuous_in_time():
    path = resolve(ORBIT)
    h = 1e-5
    for t in (1.0, 2.5):  # the interior keyframes, where segments of different lengths and durations meet
        eye = views(path, [t - h, t, t + h])[0]
        before, after = (eye[1] - eye[0]) / h, (eye[2] - eye[1]) / h
        assert np.linalg.norm(after - before) < 1e-3 * np.linalg.norm(before)
    # a keyframe where the eye rests: velocity zero there, and the eye holds between equal eyes
    rest = resolve([key(0, (0, 1, 5)), key(1, (1, 1, 5)), key(2, (1, 1, 5), (3, 1, 0)), key(3, (2, 1, 4))])
    eye = views(rest, np.linspace(1, 2, 11))[0]
    np.testing.assert_allclose(eye, np.tile([1.0, 1.0, 5.0], (11, 1)), atol=1e-12)
    eye = views(rest, [2 - h, 2, 2 + h])[0]
    assert np.linalg.norm(eye[2] - eye[1]) / h < 1e-3


def test_keyframes_on_a_line_keep_the_eye_on_it_and_moving_forward():
    keys = [key(0, (0, 1, 5)), key(0.2, (0.1, 1, 5)), key(2, (4, 1, 5)), key(2.3, (4.2, 1, 5))]
    eye = views(resolve(keys), np.linspace(0, 2.3, 200))[0]
    np.testing.assert_allclose(eye[:, 1:], np.tile([1.0, 5.0], (200, 1)), atol=1e-9)
    assert np.all(np.diff(eye[:, 0]) > 0)  # centripetal with a monotone time map: no stop, no going back


def test_turning_on_the_spot_never_flips_the_view():
    """Half a turn in place: the look-at points pass through the eye, the view turns steadily instead."""
    path = resolve([key(0, (0, 0, 0), (0, 0, -1)), key(2, (0, 0, 0), (0, 0, 1))], fps=60)
    _, forward, up, _, _ = views(path, path.frame_times())
    steps = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", forward[1:], forward[:-1]), -1, 1)))
    assert steps.sum() == pytest.approx(180.0, abs=1e-6)  # one way round, never back
    assert steps.max() < 10.0
    np.testing.assert_allclose(up, np.tile([0.0, 1.0, 0.0], (len(up), 1)), atol=1e-9)
    # a rolled keyframe: up turns with it, the shorter way
    rolled = resolve([key(0, (0, 0, 0), (0, 0, -1)), key(1, (0, 0, 0), (0, 0, -1), up=[1, 0, 0])])
    up = views(rolled, np.linspace(0, 1, 21))[2]
    assert np.all(up[:, 0] >= -1e-12) and np.all(up[:, 1] >= -1e-12)


def test_fov_and_scene_time_stay_within_their_neighbours():
    keys = [key(0, (0, 1, 5), fov=30), key(1, (5, 1, 0), fov=90, scene_time=10), key(2, (0, 1, -5), fov=31)]
    _, _, _, fov, scene_time = views(resolve(keys), np.linspace(0, 2, 101))
    assert fov.min() >= 30 - 1e-9 and fov.max() <= 90 + 1e-9
    assert np.all(np.diff(fov[:51]) >= 0) and np.all(np.diff(fov[50:]) <= 0)
    # no scene time on the last keyframe: the scene's clock runs on from the previous one's
    assert scene_time[-1] == pytest.approx(11.0)
    assert np.all(np.diff(scene_time) >= 0)


def test_a_loop_closes_smoothly_and_leaves_out_the_repeated_frame():
    path = resolve(ORBIT, fps=12, loop=True)
    assert path.end == pytest.approx(4.0)  # one mean interval after the last keyframe
    assert path.frame_count == 48  # 4 s at 12 fps, without the frame at 4 s (it is frame 0 again)
    h = 1e-5
    eye, forward, _, fov, scene_time = views(path, [0, h, 4 - h, 4])
    np.testing.assert_allclose(eye[3], eye[0], atol=1e-9)
    np.testing.assert_allclose(forward[3], forward[0], atol=1e-9)
    assert fov[3] == pytest.approx(fov[0])
    np.testing.assert_allclose((eye[1] - eye[0]) / h, (eye[3] - eye[2]) / h, rtol=1e-3, atol=1e-3)
    assert scene_time[3] == pytest.approx(4.0)  # time itself does not loop


AT_THE_LIMIT = [
    key(0, (0, 0, 5), (-1e9, 0, 0)),
    key(1, (0, 0, 6), (-1e9, 1e9, 0)),
    key(2, (0, 0, 6), (-1e9, 0, -1e9)),
]


@pytest.mark.parametrize(
    ("change", "names"),
    [
        (lambda p: p.update(keyframes=p["keyframes"][:1]), "keyframes: List should have at least 2 items"),
        (lambda p: p["keyframes"][2].update(t=0.5), "keyframes.2.t: must be greater"),
        # keyframes too close for a curve's slopes (scipy: "`dydx` must contain only finite values"), looped or not
        (lambda p: p["keyframes"][1].update(t=1e-300), "keyframes.1.t: must be greater than the previous"),
        (lambda p: p.update(loop=True, keyframes=[key(0, (0, 1, 5)), key(5e-324, (1, 1, 5))]), "by 0.001 s"),
        # keyframes at the coordinate limit whose curve reaches just past it between them
        (lambda p: p.update(keyframes=AT_THE_LIMIT), "the camera of frame 1 (t = 0.0416667 s), between them"),
        (lambda p: p["keyframes"][1].update(eye=[0, "x", 0]), "keyframes.1.eye.1"),
        (lambda p: p["keyframes"][1].update(fov=180), "keyframes.1.fov"),
        (lambda p: p["keyframes"][0].update(t=-1), "keyframes.0.t"),
        (lambda p: p["keyframes"][3].update(look_at=[-5, 1, 0]), "keyframes.3: eye and look_at coincide"),
        (lambda p: p["keyframes"][1].update(up=[-1, 0, 0]), "keyframes.1: up is parallel"),
        (lambda p: p["keyframes"][1].update(speed=2), "keyframes.1.speed: Extra inputs"),
        (lambda p: p.update(fps=0), "fps: Input should be greater than 0"),
        (lambda p: p.update(fps=240, keyframes=[key(0, (0, 1, 5)), key(3600, (1, 1, 5))]), f"{MAX_FRAMES:,}"),
    ],
)
def test_a_bad_path_is_refused_in_one_line_naming_the_field(change, names):
    raw = {"fps": 24, "keyframes": [dict(k) for k in ORBIT]}
    change(raw)
    with pytest.raises(PathError) as caught:
        parse_path(json.dumps(raw)).resolve(SCENE_CAMERA)
    assert names in str(caught.value)
    assert "\n" not in str(caught.value)


def test_non_finite_numbers_and_broken_json_are_refused(tmp_path):
    text = json.dumps({"keyframes": ORBIT}).replace("5", "NaN", 1)
    with pytest.raises(PathError, match=r"keyframes\.0\.eye\.2"):
        parse_path(text)
    broken = tmp_path / "walk.json"
    broken.write_text('{"keyframes": [')
    with pytest.raises(PathError, match=r"walk\.json: .*EOF"):
        load_path(broken, SCENE_CAMERA)
    with pytest.raises(PathError, match="missing.json"):
        load_path(tmp_path / "missing.json", SCENE_CAMERA)


def test_a_resolved_path_writes_itself_with_every_default_filled_in():
    path = resolve(ORBIT, fps=30)
    again = parse_path(path.to_json()).resolve(Camera((9.0, 9.0, 9.0), (0.0, 0.0, 0.0), fov=10.0))
    assert again == path


def test_a_path_holds_one_projection_stereo_and_ipd_from_start_to_end():
    keys = [key(0, (0, 1, 5)), {**key(1, (5, 1, 0)), "projection": "equirect", "stereo": "top-bottom", "ipd": 0.2}]
    path = resolve(keys)
    cameras, _ = path.at(np.linspace(0, 1, 7))
    assert {(c.projection, c.stereo, c.ipd) for c in [*path.cameras, *cameras]} == {("equirect", "top-bottom", 0.2)}
    assert json.loads(path.to_json())["keyframes"][0]["projection"] == "equirect"
    with pytest.raises(PathError, match=r"keyframes.1.projection: a path keeps one projection"):
        resolve([{**key(0, (0, 1, 5)), "projection": "perspective"}, {**key(1, (5, 1, 0)), "projection": "equirect"}])
