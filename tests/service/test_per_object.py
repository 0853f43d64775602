"""Settings per object and per material reach every caller: REST, the walk-through, videos and ``rcp render
--paint``, each giving the engine's painting with them; a name the scene does not have is refused in one line."""

from __future__ import annotations

import json

import httpx
import numpy as np
from helpers.wire import decode, post
from PIL import Image

from rcp_server.cli import main
from rcp_server.painting.loop import paint
from rcp_server.util import images

SCENE = "default"  # the village: walls, roofs, the well ... by name
W, H = 64, 36
QUALITY = 95
OWN = {"lambda_p": 12.0, "objects": {"walls": {"lambda_p": 0.0}, "roofs": {"mapping": "normal", "lambda_p": 20.0}}}


def _engine(server, settings: dict, spp: int | None = None) -> np.ndarray:
    scene = server.app.state.service.scenes[SCENE]
    params = scene.painting({**settings, **({"spp": spp} if spp else {})})
    return images.to_uint8(paint(scene, scene.camera, W, H, params).image)


def test_rest_paints_per_object_settings_as_the_engine(live_server):
    response = post(live_server, {"scene": SCENE, "width": W, "height": H, "paint": OWN})
    assert response.status_code == 200, response.text
    expected = _engine(live_server, OWN)
    np.testing.assert_array_equal(decode(response.content), expected)
    assert not np.array_equal(expected, _engine(live_server, {"lambda_p": 12.0}))


def test_unknown_names_are_a_422_in_one_line(live_server):
    for paint_, needle in (
        ({"objects": {"figure": {"lambda_p": 0}}}, "objects: this scene has no 'figure' (it has: 'ground'"),
        ({"materials": {"stone": {"lambda_p": 0}}}, "materials: this scene has no 'stone'"),
        ({"objects": {"walls": {"iterations": 2}}}, "Extra inputs are not permitted"),
    ):
        response = post(live_server, {"scene": SCENE, "width": W, "height": H, "paint": paint_})
        assert response.status_code == 422, response.text
        detail = response.json()["detail"]
        assert needle in str(detail) and "\n" not in str(detail)
    keyframes = [{"t": t, "eye": [0, 2, 9 - t], "look_at": [0, 1, 0]} for t in (0.0, 1.0)]
    video = {"scene": SCENE, "path": {"keyframes": keyframes, "fps": 2}, "width": W, "height": H}
    response = httpx.post(
        f"{live_server.url}/api/videos", json={**video, "paint": {"objects": {"figure": {}}}}, timeout=60
    )
    assert response.status_code == 422 and "no 'figure'" in response.text


def test_the_scene_names_its_objects_and_materials(live_server):
    info = httpx.get(f"{live_server.url}/api/scenes", timeout=30).json()
    village = next(s for s in info if s["name"] == SCENE)
    assert {"walls", "roofs", "well"} <= set(village["objects"])


def test_the_walk_through_paints_per_object_settings_as_the_engine(live_server, walk_to):
    walk = walk_to(live_server)
    walk.send(type="hello", scene=SCENE, width=W, height=H, quality=QUALITY)
    assert walk.next()["type"] == "ready"
    walk.until_final()
    walk.send(type="paint", **OWN)
    meta, image = walk.until_final()[-1]
    assert meta["paint"]["objects"] == OWN["objects"]
    expected = _engine(live_server, OWN, spp=meta["spp"])
    np.testing.assert_array_equal(image, decode(images.encode(expected / 255.0, "JPEG", QUALITY)))
    walk.send(type="paint", objects={"nobody": {"lambda_p": 0}})
    reply = walk.next()
    while reply["type"] == "frame":
        walk.ws.recv(30)
        reply = walk.next()
    assert reply["type"] == "error" and "no 'nobody'" in reply["message"]


def test_the_command_line_takes_them_from_json_or_toml(tmp_path, live_server):
    expected = _engine(live_server, OWN)
    given = tmp_path / "own.json"
    given.write_text(json.dumps(OWN))
    toml = tmp_path / "own.toml"
    toml.write_text(
        'lambda_p = 12.0\n[objects.walls]\nlambda_p = 0.0\n[objects.roofs]\nmapping = "normal"\nlambda_p = 20.0\n'
    )
    for source in (given, toml):
        out = tmp_path / f"{source.suffix[1:]}.png"
        argv = ["-q", "render", SCENE, "--out", str(out), "--width", str(W), "--height", str(H), "--paint", str(source)]
        assert main(argv) == 0
        np.testing.assert_array_equal(np.asarray(Image.open(out)), expected)


def test_the_command_line_refuses_a_bad_file_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    for text, needle in (
        ("{not json", "not valid JSON"),
        ('{"objects": {"figure": {"lambda_p": 0}}}', "no 'figure'"),
        ('{"colour": 1}', "unknown settings ['colour']"),
        ('{"objects": {"walls": {"lambda_p": "far"}}}', "objects.walls: lambda_p must be a number"),
    ):
        bad.write_text(text)
        assert main(["render", SCENE, "--out", str(tmp_path / "x.png"), "--paint", str(bad)]) == 2
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1, err


def test_the_walk_through_says_what_a_pixel_shows(live_server, walk_to):
    walk = walk_to(live_server)
    walk.send(type="hello", scene=SCENE, width=W, height=H, quality=QUALITY)
    assert walk.next()["type"] == "ready"
    scene = live_server.app.state.service.scenes[SCENE]
    shows = paint(scene, scene.camera, W, H, scene.painting({"objects": {"walls": {}}, "iterations": 1})).state.object
    names = scene.geometry()[0].object_names
    answers = {}
    for x, y in ((W // 2, H - 1), (W // 2, 0), (3, H // 2)):
        walk.send(type="pick", x=x, y=y)
        reply = walk.next()
        while reply["type"] != "picked":
            assert reply["type"] == "frame", reply
            walk.ws.recv(30)
            reply = walk.next()
        index = int(shows[y * W + x])
        assert (reply["x"], reply["y"]) == (x, y)
        assert reply["object"] == (names[index] if index >= 0 else None)
        answers[x, y] = reply["object"]
    assert answers[W // 2, 0] is None and answers[W // 2, H - 1] == "ground"  # the sky above, the ground below
    walk.send(type="pick", x=W, y=0)
    reply = walk.next()
    while reply["type"] == "frame":
        walk.ws.recv(30)
        reply = walk.next()
    assert reply["type"] == "error" and f"not in a {W}x{H} view" in reply["message"]
