"""Painting on a real local Ray runtime: the same frames as the threads, pixel for pixel, per frame and
temporal (bands for the ray-traced method, whole frames for the image method); a worker lost mid-job and an
address that does not answer are one-line errors in bounded time."""

from __future__ import annotations

import io
import os
import signal
import socket
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ray = pytest.importorskip("ray")  # the cluster extra; the test extra installs it

from rcp_server.cli import main  # noqa: E402
from rcp_server.cluster.painter import Backoff, ClusterError, RayPainter, check_address, connect  # noqa: E402
from rcp_server.media.camerapath import parse_path  # noqa: E402
from rcp_server.painting.loop import Abandoned, paint  # noqa: E402
from rcp_server.painting.sequence import paint_sequence  # noqa: E402
from rcp_server.settings.params import PaintParams  # noqa: E402
from rcp_server.util import images  # noqa: E402

W, H = 40, 30
PATH = {
    "fps": 4,
    "keyframes": [
        {"t": 0, "eye": [0, 0, 0], "look_at": [0, 0, -1]},
        {"t": 1, "eye": [0.5, 0.3, -0.5], "look_at": [-0.2, 0, -4.5], "fov": 50},
    ],
}

TINY = """
[camera]
eye = [0, 1, 4]
look_at = [0, 0.5, 0]
[environment]
color = [0.2, 0.5, 0.9]
[[objects]]
primitive = { type = "box", extents = [1, 1, 1] }
color = [0.9, 0.2, 0.1]
spin = { degrees_per_second = 90 }
"""


@pytest.fixture(scope="module")
def painter():
    """One small local Ray runtime for the module (two CPUs, no dashboard), shut down after it."""
    started = connect(None, num_cpus=2, object_store_memory=128 << 20)
    painter = RayPainter()
    yield painter
    painter.close()
    if started:
        ray.shutdown()


def shots(scene, path=PATH):
    return list(parse_path(path).resolve(scene.camera).frames())


def threaded(scene, params, temporal=None, path=PATH) -> list[np.ndarray]:
    def paint_frame(camera, scene_time, frame_params, previous):
        return paint(scene, camera, W, H, frame_params, time=scene_time, previous=previous, threads=2)

    return [images.to_uint8(i) for i in paint_sequence(paint_frame, shots(scene, path), params, temporal)]


@pytest.mark.parametrize(
    ("settings", "temporal"),
    [
        ({"spp": 2, "lambda_p": 6.0}, None),  # per frame: frames go round the actors
        ({"spp": 2, "lambda_p": 6.0, "lambda_e": 0.05}, 2),  # temporal, traced: bands through every frame
        ({"mapping": "depth", "lambda_p": 6.0, "method": "image"}, 1),  # temporal, image method: whole frames
    ],
)
def test_ray_paints_the_threads_frames_pixel_for_pixel(painter, busy_scene, settings, temporal):
    params = replace(PaintParams(iterations=3), **settings)
    expected = threaded(busy_scene, params, temporal)
    got = list(painter.images(busy_scene, shots(busy_scene), W, H, params, temporal))
    assert len(got) == len(expected) == 5
    for frame, painting in zip(got, expected, strict=True):
        assert frame.dtype == np.uint8
        np.testing.assert_array_equal(frame, painting)
    assert not np.array_equal(got[0], got[-1])


def test_rcp_render_ray_writes_the_same_frames(painter, tmp_path):
    scene = tmp_path / "tiny.toml"
    scene.write_text(TINY)
    argv = ["-q", "render", str(scene), "--width", "32", "--height", "24", "--frames", "3", "--temporal", "1"]
    painter.close()  # its actors hold the runtime's two CPUs; the command's would wait for them
    assert main([*argv, "--out", str(tmp_path / "here")]) == 0
    assert main([*argv, "--out", str(tmp_path / "ray"), "--ray"]) == 0
    for k in range(3):
        here = np.asarray(Image.open(tmp_path / "here" / f"frame_{k:04d}.png"))
        np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "ray" / f"frame_{k:04d}.png")), here)
    assert ray.is_initialized()  # the command used the runtime it found and left it running


def long_path(seconds: float) -> dict:
    return {**PATH, "fps": 30, "keyframes": [PATH["keyframes"][0], {**PATH["keyframes"][1], "t": seconds}]}


def test_one_large_painting_in_bands_is_the_threads_painting(painter, busy_scene):
    """A REST render on Ray: a band of rows per actor (the image method's whole on one)."""
    camera = shots(busy_scene)[2].camera
    for params in (PaintParams(iterations=4, spp=2), PaintParams(iterations=3, method="image", lambda_p=6.0)):
        expected = images.to_uint8(paint(busy_scene, camera, W, H, params, time=0.25, threads=2).image)
        got = painter.render(busy_scene, camera, W, H, params, time=0.25)
        assert got.dtype == np.uint8
        np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize(
    "view",
    [
        {"projection": "equirect"},
        {"stereo": "top-bottom", "ipd": 0.2},
        {"projection": "equirect", "stereo": "side-by-side"},
    ],
)
def test_a_panorama_or_a_stereo_pair_in_bands_is_the_threads_painting(painter, busy_scene, view):
    camera = shots(busy_scene)[2].camera.moved(**view)
    width, height = camera.image_size(2 * H, H)
    params = PaintParams(iterations=4, lambda_p=10.0)
    expected = images.to_uint8(paint(busy_scene, camera, width, height, params, time=0.25, threads=2).image)
    np.testing.assert_array_equal(painter.render(busy_scene, camera, width, height, params, time=0.25), expected)


def test_paintings_of_two_scenes_share_the_workers_at_once(painter, busy_scene, gradient_scene):
    """A sequence of one scene and a painting of another, interleaved on the same actors."""
    params = PaintParams(iterations=2)
    frames = painter.images(busy_scene, shots(busy_scene), W, H, params)
    first = next(frames)
    other = painter.render(gradient_scene, gradient_scene.camera, W, H, params)
    rest = list(frames)
    expected = threaded(busy_scene, params)
    for frame, painting in zip([first, *rest], expected, strict=True):
        np.testing.assert_array_equal(frame, painting)
    np.testing.assert_array_equal(
        other, images.to_uint8(paint(gradient_scene, gradient_scene.camera, W, H, params, threads=2).image)
    )


def crash(actors) -> None:
    """Kill the workers' processes, as a machine that goes down would: Ray restarts them (not ``ray.kill``)."""
    for pid in ray.get([actor.pid.remote() for actor in actors]):
        os.kill(pid, signal.SIGKILL)


def test_a_worker_that_dies_is_restarted_and_its_frames_painted_again(painter, busy_scene):
    params = PaintParams(iterations=2)
    path = long_path(0.5)
    frames = painter.images(busy_scene, shots(busy_scene, path), W, H, params)
    got = [next(frames)]
    crash(painter.actors())
    got += list(frames)
    expected = threaded(busy_scene, params, path=path)
    assert len(got) == len(expected) == 16
    for frame, painting in zip(got, expected, strict=True):
        np.testing.assert_array_equal(frame, painting)


@pytest.mark.parametrize("settings", [{}, {"mapping": "depth", "lambda_p": 6.0, "method": "image"}])
def test_a_temporal_band_lost_with_its_worker_is_painted_again_and_the_film_is_the_threads(
    painter, busy_scene, settings
):
    """Ray restarts the worker empty: its band is painted again from the first frame, the film goes on."""
    params = replace(PaintParams(iterations=2), **settings)
    path = long_path(0.5)
    frames = painter.images(busy_scene, shots(busy_scene, path), W, H, params, temporal=1)
    got = [next(frames), next(frames), next(frames)]
    crash(painter.actors())
    got += list(frames)
    expected = threaded(busy_scene, params, temporal=1, path=path)
    assert len(got) == len(expected) == 16
    for frame, painting in zip(got, expected, strict=True):
        np.testing.assert_array_equal(frame, painting)


@pytest.mark.parametrize("temporal", [None, 1])
def test_a_worker_gone_for_good_is_replaced_and_only_its_frames_painted_again(painter, busy_scene, temporal):
    params = PaintParams(iterations=2)
    path = long_path(0.5)
    frames = painter.images(busy_scene, shots(busy_scene, path), W, H, params, temporal)
    got = [next(frames), next(frames)]
    crew = painter.actors()
    ray.kill(crew[0])  # no restart: a node gone
    got += list(frames)
    expected = threaded(busy_scene, params, temporal, path=path)
    assert len(got) == len(expected) == 16
    for frame, painting in zip(got, expected, strict=True):
        np.testing.assert_array_equal(frame, painting)
    after = painter.actors()
    assert after[0] != crew[0] and after[1:] == crew[1:]  # the other worker kept its place and its work


def test_a_painting_no_longer_wanted_stops_waiting(painter, busy_scene):
    params = PaintParams(iterations=6, spp=4)
    asked = []
    with pytest.raises(Abandoned):  # a painting that is not heard out returns its image instead
        painter.render(busy_scene, busy_scene.camera, 640, 480, params, should_stop=lambda: not asked.append(1))
    assert len(asked) == 1  # asked at the first wait, and nothing waited on after


def test_an_address_that_does_not_answer_is_one_line_in_bounded_time(capsys, tmp_path):
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    # bounded by what it says: refused at once, not a wait on a timeout
    with pytest.raises(ClusterError, match=rf"Ray address 127.0.0.1:{port} does not answer \(Connection refused\)"):
        check_address(f"127.0.0.1:{port}", timeout_s=2.0)
    with pytest.raises(ClusterError, match="is not host:port"):
        check_address("nowhere")
    argv = ["render", "sky", "--width", "16", "--height", "16", "--out", str(tmp_path / "s.png")]
    assert main([*argv, "--ray", f"ray://127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"rcp: error: Ray address ray://127.0.0.1:{port} does not answer (Connection refused)"]


def test_the_server_paints_videos_and_large_renders_on_ray_when_told_to(painter, tmp_path):
    """``RCP_RAY_ADDRESS``: the same video and the same PNG as the server's own threads paint."""
    import av
    import httpx
    from helpers.servers import BackgroundServer, job_status

    (tmp_path / "tiny.toml").write_text(TINY)
    body = {"scene": "tiny", "path": PATH, "width": 32, "height": 24, "temporal": 1, "paint": {"spp": 2}}
    render = {"scene": "tiny", "width": 48, "height": 36, "time": 0.5, "paint": {"spp": 2}}
    painter.close()  # the server's actors need the runtime's CPUs

    def served(**settings) -> tuple[list[np.ndarray], bytes]:
        with BackgroundServer(scenes=tmp_path, **settings) as live, httpx.Client(base_url=live.url) as client:
            png = client.post("/api/render", json=render, timeout=60)
            assert png.status_code == 200, png.text
            job = client.post("/api/videos", json=body).json()
            status = job_status(client, f"/api/videos/{job['id']}")
            assert status["state"] == "done", status
            data = client.get(f"/api/videos/{job['id']}/file").content
        with av.open(io.BytesIO(data)) as container:
            return [f.to_ndarray(format="rgb24") for f in container.decode(video=0)], png.content

    (on_ray, ray_png), (here, here_png) = served(ray_address="local", ray_min_work=1), served()
    assert len(on_ray) == len(here) == 5
    for a, b in zip(on_ray, here, strict=True):
        np.testing.assert_array_equal(a, b)
    assert ray_png == here_png


def test_a_film_on_ray_stops_at_the_next_frame_once_it_is_no_longer_wanted(painter, busy_scene):
    """Frames quicker than a wait's poll: the film stops at the next frame all the same, not at its end."""
    frames = []
    film = painter.images(
        busy_scene, shots(busy_scene, long_path(3.0)), W, H, PaintParams(iterations=1), None, lambda: len(frames) >= 2
    )
    with pytest.raises(Abandoned):
        for image in film:
            frames.append(image)
    assert len(frames) == 2


def test_a_video_on_ray_stopped_mid_way_resumes_after_a_restart(painter, tmp_path, caplog):
    """A server painting on Ray stops mid-film; started again on the same data folder, it goes on from the last
    frame written (a temporal job paints up to there again on the actors), and the film is the threads' one.

    The film is long (91 frames of 32x24) so that it is stopped mid-way: Ray paints on between the moment two
    frames are seen written and the moment the stopping server cancels the job (a 31-frame film was seen
    painted whole meanwhile, when a cancelled job stopped only at a frame that made it wait)."""
    import av
    import httpx
    from helpers.servers import FINISHED, BackgroundServer, job_status

    from rcp_server.service.store import Store

    caplog.set_level("INFO", "rcp.service")
    (tmp_path / "tiny.toml").write_text(TINY)
    data = tmp_path / "data"
    path = long_path(3.0)
    painter.close()  # the server's actors need the runtime's CPUs
    films = {}
    for temporal in (None, 1):
        body = {"scene": "tiny", "path": path, "width": 32, "height": 24, "temporal": temporal}
        with BackgroundServer(scenes=tmp_path, data=data, ray_address="local") as live:
            with httpx.Client(base_url=live.url, timeout=60) as client:
                job = client.post("/api/videos", json=body).json()
                # a fresh clone's actors load the kernels first
                status = job_status(
                    client, f"/api/videos/{job['id']}", lambda s: s["done_frames"] >= 2 or s["state"] in FINISHED, 180
                )
        assert status["state"] == "running" and status["done_frames"] < job["frames"] == 91
        with Store(data) as store:  # as the stopped server left it: mid-way, to be resumed
            (left,) = [r for r in store.videos() if r.id == job["id"]]
        assert left.state == "running" and left.done_frames < left.frames, left
        for where in ({"ray_address": "local"}, {}):  # resumed on Ray; then the same film on threads
            with BackgroundServer(scenes=tmp_path, data=data, **where) as live:
                with httpx.Client(base_url=live.url, timeout=60) as client:
                    if where:
                        video_id = job["id"]
                    else:
                        video_id = client.post("/api/videos", json=body).json()["id"]
                    status = job_status(client, f"/api/videos/{video_id}")
                    assert status["state"] == "done", status
                    if where:
                        assert any(m.startswith(f"video {job['id']} resumes at frame ") for m in caplog.messages)
                    data_file = client.get(f"/api/videos/{video_id}/file").content
            with av.open(io.BytesIO(data_file)) as container:
                films[temporal, bool(where)] = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
        for resumed, here in zip(films[temporal, True], films[temporal, False], strict=True):
            np.testing.assert_array_equal(resumed, here)


@pytest.mark.parametrize("listening", [False, True])
def test_rcp_serve_with_a_ray_that_does_not_answer_fails_to_start_in_one_line(tmp_path, listening):
    """``RCP_RAY_ADDRESS`` is joined at start-up: an address nobody listens at, or one that takes connections
    but never speaks Ray's protocol, is one line and exit status 2, in bounded time (``RCP_RAY_JOIN_S``)."""
    import subprocess
    import sys

    from helpers.servers import free_port, rcp_environment

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        if listening:
            probe.listen()
        address = f"127.0.0.1:{probe.getsockname()[1]}"
        env = rcp_environment(data=str(tmp_path), ray_address=address)
        started = subprocess.run(
            [sys.executable, "-m", "rcp_server.cli", "serve", "--port", str(free_port())],
            env={**env, "RCP_RAY_JOIN_S": "3"},
            capture_output=True,
            text=True,
            timeout=60,
        )
    said = (
        f"Ray at {address} was not joined within 3 s (RCP_RAY_JOIN_S)"
        if listening
        else f"Ray address {address} does not answer (Connection refused)"
    )
    assert started.returncode == 2, started.stderr
    assert started.stderr.strip().splitlines() == [f"rcp: error: {said}"]  # bounded by the join's limit, or refused


def test_ray_backs_off_after_a_failure_and_doubles_its_wait():
    now = [100.0]
    backoff = Backoff(first_s=5.0, most_s=30.0, clock=lambda: now[0])
    assert backoff.wait_s() == 0
    waits = []
    for _ in range(5):
        backoff.failed("Ray is down")
        waits.append(backoff.wait_s())
    assert waits == [5.0, 10.0, 20.0, 30.0, 30.0]
    now[0] += 29.0
    assert backoff.wait_s() == 1.0
    backoff.succeeded()
    assert backoff.wait_s() == 0 and backoff.failures == 0
    backoff.failed("again")
    assert backoff.wait_s() == 5.0


def test_a_server_whose_ray_failed_paints_here_meanwhile_and_says_so_at_once(painter, tmp_path, busy_scene):
    """While Ray backs off, a large REST render is painted on the server's own threads (the same PNG), and a
    painting asked of Ray fails at once rather than waiting for it."""
    import httpx
    from helpers.servers import BackgroundServer

    from rcp_server.service.state import service_of

    (tmp_path / "tiny.toml").write_text(TINY)
    large = {"scene": "tiny", "width": 64, "height": 48, "paint": {"spp": 2, "iterations": 2}}
    painter.close()  # the server's actors need the runtime's CPUs
    with BackgroundServer(scenes=tmp_path, ray_address="local", ray_min_work=1) as live:
        cluster = service_of(live.app).painter.cluster
        with httpx.Client(base_url=live.url, timeout=60) as client:
            on_ray = client.post("/api/render", json=large)
            assert on_ray.status_code == 200
            cluster.backoff.failed("a Ray worker was lost mid-job: gone")
            here = client.post("/api/render", json=large)
            assert here.status_code == 200 and here.content == on_ray.content
            with pytest.raises(
                ClusterError, match=r"^a Ray worker was lost mid-job: gone \(Ray is tried again in 5 s\)$"
            ):
                cluster.render(busy_scene, busy_scene.camera, W, H, PaintParams(iterations=2))


def _swirl(data):
    """A mapping registered in this process only: the color field turned about the view axis."""
    return np.cross(data.forward, data.color_field()).astype(np.float32)


def _broken_field(data):
    """A mapping that fails wherever it runs: its exception is what the user must read."""
    raise ArithmeticError(f"no field for {len(data.forward)} samples here")


def test_a_painting_that_fails_on_ray_says_the_workers_exception_in_one_line(painter, busy_scene):
    """The worker's exception type and message reach the one line the caller sees, not Ray's
    ``ray::Painter.band()``."""
    from rcp_server.cluster.painter import PaintingFailed
    from rcp_server.settings.mappings import register_mapping, unregister_mapping

    register_mapping("test-broken", {"color"}, _broken_field)
    try:
        params = PaintParams(iterations=2, mapping="test-broken", lambda_p=4.0)
        with pytest.raises(PaintingFailed) as failed:
            painter.render(busy_scene, busy_scene.camera, W, H, params)
        message = str(failed.value)
        assert "\n" not in message
        assert message.startswith("a painting failed on Ray: ArithmeticError: no field for "), message
        assert message.endswith(" samples here"), message
    finally:
        unregister_mapping("test-broken")


def test_a_registered_mapping_paints_on_ray_as_on_threads(painter, busy_scene):
    from rcp_server.settings.mappings import register_mapping, unregister_mapping

    register_mapping("test-swirl", {"color"}, _swirl)
    try:
        params = PaintParams(iterations=3, mapping="test-swirl", lambda_p=8.0, objects={"red": {"lambda_p": 0.0}})
        expected = images.to_uint8(paint(busy_scene, busy_scene.camera, W, H, params, threads=2).image)
        assert not np.array_equal(
            expected, images.to_uint8(paint(busy_scene, busy_scene.camera, W, H, replace(params, iterations=1)).image)
        )
        np.testing.assert_array_equal(painter.render(busy_scene, busy_scene.camera, W, H, params), expected)
        frames = list(painter.images(busy_scene, shots(busy_scene), W, H, params, None))
        np.testing.assert_array_equal(frames, threaded(busy_scene, params))
    finally:
        unregister_mapping("test-swirl")


def _descendants(pid: int) -> list[str]:
    """The command names of a process's descendants (``/proc``): Ray's runtime runs under the server's driver."""
    parents: dict[int, tuple[int, str]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text()
        except OSError:  # gone meanwhile
            continue
        name, rest = fields[fields.index("(") + 1 : fields.rindex(")")], fields[fields.rindex(")") + 2 :].split()
        parents[int(stat.parent.name)] = (int(rest[1]), name)
    found, frontier = [], {pid}
    while frontier:
        children = {child for child, (parent, _) in parents.items() if parent in frontier}
        found += [parents[child][1] for child in children]
        frontier = children
    return found


@pytest.mark.parametrize("joined", [False, True])
def test_rcp_serve_exits_0_on_sigterm_with_ray_joined_or_not(tmp_path, joined):
    """``ray.init`` puts its own SIGTERM handler in place (exit status 15): ``rcp serve`` keeps its own, and a
    stop asked for is a clean exit, 0, with Ray's runtime stopped with it."""
    from helpers.servers import rcp_serve
    from helpers.waits import wait_until

    settings = {"ray_address": "local", "ray_walks": "0"} if joined else {}
    with rcp_serve(tmp_path, **settings) as served:
        if joined:  # a local Ray runtime of the server's own
            # the driver starts the runtime off the serving path
            wait_until(lambda: {"raylet", "gcs_server"} <= set(_descendants(served.process.pid)), pause=0.2)
        served.process.send_signal(signal.SIGTERM)
        assert served.process.wait(120) == 0, served.log.read_text()[-2000:]
    assert "Traceback" not in served.log.read_text()
