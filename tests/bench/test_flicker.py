"""``rcp bench flicker``: the warping error is exact where it should be (a still film, a plain film near its
floor), and large for a pattern fixed to the screen (the shower door); the command prints the table and ends
with the painted-to-plain ratio."""

from __future__ import annotations

import json
import re
from dataclasses import replace

import numpy as np
import pytest

from rcp_server.bench.flicker import Warps, films, sight, warp
from rcp_server.cli import main
from rcp_server.media.camerapath import parse_path
from rcp_server.painting.loop import paint
from rcp_server.settings.params import PaintParams

W, H = 64, 40


def pan(scene, end=(0.3, 0.05, -0.2), frames=9):
    last = {"t": (frames - 1) / 8, "eye": list(end), "look_at": [end[0] - 0.1, end[1], -1]}
    spec = {"fps": 8, "keyframes": [{"t": 0, "eye": [0, 0, 0], "look_at": [0, 0, -1]}, last]}
    return list(parse_path(spec).resolve(scene.camera).frames())


def test_the_warp_of_a_frame_into_itself_is_the_identity(busy_scene):
    shot = pan(busy_scene)[3]
    seen = sight(busy_scene, shot.camera, W, H, 0.0)
    w = warp(seen, shot.camera, seen, W, H)
    j, i = np.divmod(np.arange(W * H), W)
    # all but the pixels beside an edge (whose four neighbours see two surfaces): the border kept
    assert w.mask.mean() > 0.85 and w.mask.reshape(H, W)[1:-1, [0, -1]].mean() > 0.5
    np.testing.assert_allclose(w.x[w.mask], i[w.mask], atol=1e-4)
    np.testing.assert_allclose(w.y[w.mask], j[w.mask], atol=1e-4)


def test_a_plain_film_is_near_its_floor_and_the_shower_door_is_large(busy_scene):
    shots = pan(busy_scene)
    warps = Warps(busy_scene, shots, W, H)
    painted = films(busy_scene, shots, W, H, PaintParams(lambda_p=6.0), temporal=1)
    plain = painted["plain"]()
    measured = warps.measure(plain)
    # the plain film's floor: its own frames warped into themselves are exact; along the pan, resampling alone
    still = Warps(busy_scene, [shots[0]] * 9, W, H).measure([plain[0]] * 9)
    assert all(e < 1e-12 for e in still.error.values())  # rounding of the bilinear weights alone
    assert all(0 < e < 5e-3 for e in measured.error.values()), measured
    assert all(0.5 < c <= 1.0 for c in measured.compared.values())
    # a pattern fixed to the screen over the same film: the shower door
    door = np.random.default_rng(0).uniform(-0.15, 0.15, (H, W, 3))
    shower = warps.measure([np.clip(f + door, 0, 1) for f in plain])
    assert all(shower.error[g] > 10 * measured.error[g] for g in (1, 7)), (shower, measured)
    # the same pattern moving with the scene (warped along) is no shower door: its error stays near the floor
    per_frame = warps.measure(painted["painted, per frame"]())
    assert all(per_frame.error[g] < shower.error[g] for g in (1, 7))


def test_rcp_bench_flicker_prints_the_films_side_by_side_and_ends_with_the_ratio(tmp_path, capsys):
    path = tmp_path / "short.json"
    path.write_text(json.dumps({"fps": 4, "keyframes": [
        {"t": 0, "eye": [0.8, 1.7, 38.0], "look_at": [0.0, 3.0, 0.0]},
        {"t": 1, "eye": [0.6, 1.7, 36.0], "look_at": [0.0, 2.9, 0.0]}]}))  # fmt: skip
    assert main(["bench", "flicker", str(path), "--width", "48", "--height", "27", "--fps", "8"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("rcp bench flicker: short.json on default, 9 frames of 48x27 at 8 fps")
    assert [line.split()[0] for line in lines[2:5]] == ["plain", "painted,", "painted,"]
    assert lines[-1].startswith("painted-to-plain warping error: per frame ") and "temporal 1 " in lines[-1]
    plain = [float(v) for v in lines[2].split()[1:3]]
    (third,) = re.findall(r": plain ([\d.]+) \(t-1\), ([\d.]+) \(t-7\);", lines[-2])
    assert lines[-2].startswith("per channel, as Lai et al. 2018's released E_warp script averages: plain ")
    assert [float(v) for v in third] == pytest.approx([e / 3 for e in plain], abs=1e-6)


@pytest.mark.parametrize("boil", [0, 3])
def test_boil_paints_the_frames_with_their_seed(busy_scene, boil):
    shots = pan(busy_scene, frames=4)
    params = PaintParams(noise=0.5, boil=boil)
    frames = films(busy_scene, shots, W, H, params, temporal=1)["painted, per frame"]()
    for k, (shot, frame) in enumerate(zip(shots, frames, strict=True)):
        seed = k // boil if boil else 0
        expected = paint(busy_scene, shot.camera, W, H, replace(params, seed=seed), time=shot.scene_time).image
        np.testing.assert_array_equal(frame, expected)
