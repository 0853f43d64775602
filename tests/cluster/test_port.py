"""The painter port on a real local Ray runtime: walk frames, renders and films painted through Ray's
implementation are the local implementation's, pixel for pixel (the JPEG's bytes, for walk frames)."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

ray = pytest.importorskip("ray")  # the cluster extra; the test extra installs it

from rcp_server.cluster.admission import Target  # noqa: E402
from rcp_server.cluster.port import RayPort  # noqa: E402
from rcp_server.cluster.remote import RemoteRay, RemoteWalks  # noqa: E402
from rcp_server.media.camerapath import parse_path  # noqa: E402
from rcp_server.media.walkframe import WalkFrame  # noqa: E402
from rcp_server.service.painter import LocalPainter  # noqa: E402
from rcp_server.service.workshop import Workshop  # noqa: E402
from rcp_server.settings.params import PaintParams  # noqa: E402

W, H = 48, 32
PATH = {
    "fps": 4,
    "keyframes": [
        {"t": 0, "eye": [0, 0, 0], "look_at": [0, 0, -1]},
        {"t": 1, "eye": [0.5, 0.3, -0.5], "look_at": [-0.2, 0, -4.5], "fov": 50},
    ],
}


@pytest.fixture(scope="module")
def ports(busy_scene):
    """The local port, and Ray's as the server opens it: a driver in a child process with a runtime of its own
    (two CPUs), its walkers measured on ``busy_scene``."""
    workshop = Workshop(2, 2)
    cluster = RemoteRay("local", Target(20, W, H), 30)
    cluster.start(120)
    walks = RemoteWalks(cluster, 1, 30)
    walks.calibrate(busy_scene, PaintParams(iterations=2))
    cluster.call("target", 1.0, W, H)  # room on Ray for a walker at a frame a second, whatever the machine's load
    local, on_ray = LocalPainter(workshop), RayPort(cluster, LocalPainter(workshop), 0, walks)
    yield local, on_ray
    on_ray.close()
    workshop.close()


def test_walk_frames_through_ray_are_the_local_ones_and_keep_their_state(ports, busy_scene):
    local, on_ray = ports
    params = PaintParams(iterations=2, spp=2, lambda_p=6.0)
    for port in ports:
        port.admit("walker", params, busy_scene)
    deadline = time.monotonic() + 60  # the walker's crew starts off the frames' path: painted here meanwhile
    while on_ray.walks.frames == 0 and time.monotonic() < deadline:
        on_ray.walk_frame("walker", WalkFrame(busy_scene, busy_scene.camera, W, H, params, 0.0, 80, 100, None))
        time.sleep(0.2)
    cameras = [busy_scene.camera.moved(eye=(0.2 * k, 0.1, 0.05 * k)) for k in range(4)]
    painted = {id(port): [] for port in ports}
    for k, camera in enumerate(cameras):
        after = None if k in (0, 2) else k  # frame 3 continues frame 2's state; 2 starts afresh
        frame = WalkFrame(busy_scene, camera, W, H, params, 0.1 * k, 80, k + 1, after)
        for port in ports:
            painted[id(port)].append(port.walk_frame("walker", frame))
    frames_on_ray = on_ray.walks.frames - 1
    for here, there in zip(painted[id(local)], painted[id(on_ray)], strict=True):
        assert (here.width, here.height, here.serial, here.continued) == (
            there.width,
            there.height,
            there.serial,
            there.continued,
        )
        assert here.jpeg == there.jpeg
    assert [p.continued for p in painted[id(local)]] == [False, True, False, True]
    assert frames_on_ray == 4  # every one of them painted on Ray, none fell back
    for port in ports:
        port.leave("walker")


def test_renders_through_ray_are_the_local_ones(ports, busy_scene):
    local, on_ray = ports
    camera = busy_scene.camera.moved(eye=(0.3, 0.2, 0.1))
    for params in (PaintParams(iterations=3, spp=2), PaintParams(iterations=3, method="image", lambda_p=6.0)):
        here = local.render(busy_scene, camera, W, H, params, 0.25, None)
        there = on_ray.render(busy_scene, camera, W, H, params, 0.25, None)
        assert here.dtype == there.dtype == np.uint8 and here.shape == (H, W, 3)
        np.testing.assert_array_equal(there, here)
    assert on_ray.cluster.ready()  # Ray painted them: it never failed (a failure backs off, painted here)


@pytest.mark.parametrize(
    ("settings", "temporal"),
    [({"spp": 2, "lambda_p": 6.0}, None), ({"spp": 2, "lambda_p": 6.0, "lambda_e": 0.05}, 2)],
)
def test_films_through_ray_are_the_local_ones_from_any_frame(ports, busy_scene, settings, temporal):
    params = replace(PaintParams(iterations=3), **settings)
    path = parse_path(PATH).resolve(busy_scene.camera)
    films = [
        [image for image, _ in port.film(busy_scene, path, W, H, params, temporal, start, None, None)]
        for start in (0, 2)
        for port in ports
    ]
    assert [len(f) for f in films] == [5, 5, 3, 3]
    for here, there in ((films[0], films[1]), (films[2], films[3]), (films[0][2:], films[2])):
        for a, b in zip(here, there, strict=True):
            np.testing.assert_array_equal(a, b)
    assert not np.array_equal(films[0][0], films[0][-1])


@pytest.mark.parametrize(
    ("key", "temporal"),
    [({"mapping": "normal", "lambda_p": 10.0, "seed": 3}, None), ({"method": "image", "lambda_p": 8.0}, 2)],
)
def test_keyed_films_through_ray_are_the_local_ones(ports, busy_scene, key, temporal):
    """Each frame of a path that keys its painting travels with its own settings, a cross-fade's two paintings
    blended where they are painted (per frame: on an actor; temporal: in each band, or on one actor for all of
    a film that keys the image method anywhere)."""
    keyed = {
        **PATH,
        "keyframes": [
            {**PATH["keyframes"][0], "paint": {"lambda_p": 2.0}},
            {**PATH["keyframes"][1], "paint": key, "fade": 0.5},
        ],
    }
    params = PaintParams(iterations=2, spp=2)
    path = parse_path(keyed).resolve(busy_scene.camera).with_painting(params, busy_scene.check_names)
    assert [len(frame.looks) for frame in path.frames()] == [1, 1, 1, 2, 1]  # frame 3 is the fade's midpoint
    here, there = (
        [image for image, _ in port.film(busy_scene, path, W, H, params, temporal, 0, None, None)] for port in ports
    )
    assert len(here) == len(there) == 5
    for a, b in zip(here, there, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(here[0], here[-1])
    assert ports[1].cluster.ready()  # painted on Ray: a failure backs off, and the film would fail or paint here
