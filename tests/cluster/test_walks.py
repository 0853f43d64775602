"""Walk-throughs painted on a real local Ray runtime: the threads' frames pixel for pixel, the temporal state
kept on the worker and rebuilt after a loss, walkers admitted while there is room (then on the server's cores,
then one line) and none starving, an actor killed mid-walk, and the runtime's raylet killed and the runtime stopped
(``ray stop --force``, scoped to the server's own runtime) mid-walk: the server alive, no connection closed,
frames within seconds, REST answering, the walks back on Ray once it answers again.

The first test's runtime is this process's own; the servers' are their drivers' (a child process each)."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

ray = pytest.importorskip("ray")  # the cluster extra; the test extra installs it

from helpers.servers import BackgroundServer, get_json  # noqa: E402
from helpers.waits import wait_until  # noqa: E402
from helpers.wire import Walk  # noqa: E402
from websockets.exceptions import ConnectionClosed  # noqa: E402

from rcp_server.cluster.admission import Target  # noqa: E402
from rcp_server.cluster.connection import Connection, connect  # noqa: E402
from rcp_server.cluster.walks import NoRoom, Walks  # noqa: E402
from rcp_server.painting.loop import paint  # noqa: E402
from rcp_server.service.state import service_of  # noqa: E402
from rcp_server.settings.params import PaintParams  # noqa: E402
from rcp_server.util import images  # noqa: E402

W, H = 96, 64
TINY = """
[camera]
eye = [0, 1, 4]
look_at = [0, 0.5, 0]
[environment]
color = [0.2, 0.5, 0.9]
[[objects]]
primitive = { type = "box", extents = [1, 1, 1] }
color = [0.9, 0.2, 0.1]
"""


@pytest.fixture(scope="module")
def runtime():
    """One small local Ray runtime for the module (two CPUs, no dashboard), shut down after it."""
    started = connect(None, num_cpus=2, object_store_memory=128 << 20)
    yield
    if started and ray.is_initialized():
        ray.shutdown()


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scenes")
    (folder / "tiny.toml").write_text(TINY)
    return folder


def cameras(scene, count: int):
    return [scene.camera.moved(eye=(0.3 * k, 0.2, 0.1 * k)) for k in range(count)]


def test_walk_frames_on_ray_are_the_threads_and_the_temporal_state_is_rebuilt_after_a_loss(runtime, busy_scene):
    """Per frame and temporal, each frame is the threads' painting before encoding; the state stays on the
    worker (a frame sends the camera, not the state); killed, the actor leaves the crew (painted here meanwhile), a
    new one starts off the frames' path and the recursion starts again from ``I_0`` there, then goes on from the new
    worker's own state."""
    walks = Walks(Connection(), Target(20, W, H), 30)
    first = PaintParams(iterations=3, lambda_p=6.0, lambda_e=0.05)
    step = replace(first, iterations=1)
    walks.calibrate(busy_scene, first)
    walks.admit("w", first, busy_scene)
    try:
        shots = cameras(busy_scene, 6)

        def on_ray(k: int, params: PaintParams, after: int | None):
            deadline = time.monotonic() + 60
            while True:  # painted here while the crew starts
                try:
                    painted = walks.paint(
                        "w", busy_scene, shots[k], W, H, params, 0.1 * k, 80, k, after, keep_pixels=True
                    )
                    break
                except NoRoom:
                    assert time.monotonic() < deadline
                    time.sleep(0.05)
            assert images.encode(painted.pixels, "JPEG", 80) == painted.jpeg  # encoded on the worker
            return painted

        def here(k: int, params: PaintParams, previous):
            return paint(busy_scene, shots[k], W, H, params, time=0.1 * k, previous=previous, threads=2)

        # per frame: every frame from I_0
        painted = on_ray(0, first, None)
        np.testing.assert_array_equal(painted.pixels, images.to_uint8(here(0, first, None).image))
        assert not painted.continued
        # temporal: frames 1 and 2 go on from the state the worker keeps
        state = here(0, first, None).state
        for k in (1, 2):
            expected = here(k, step, state)
            painted = on_ray(k, step, k - 1)
            assert painted.continued
            np.testing.assert_array_equal(painted.pixels, images.to_uint8(expected.image))
            state = expected.state
        # the actor killed (a process gone, as a machine that goes down): a new one paints once it is warm
        (member,) = walks.places["w"].crew.values()
        os.kill(ray.get(member.actor.pid.remote()), signal.SIGKILL)
        painted = on_ray(3, step, 2)
        assert walks.moved == 1
        assert not painted.continued  # the state was lost with the worker: started again from I_0
        rebuilt = here(3, step, None)
        np.testing.assert_array_equal(painted.pixels, images.to_uint8(rebuilt.image))
        painted = on_ray(4, step, 3)  # and kept on the new worker from there
        assert painted.continued
        np.testing.assert_array_equal(painted.pixels, images.to_uint8(here(4, step, rebuilt.state).image))
        assert not np.array_equal(painted.pixels, images.to_uint8(here(4, step, None).image))
        # a frame after one the session did not show starts again rather than going on from the wrong state
        assert not on_ray(5, step, 3).continued
    finally:
        walks.close()


def walker(server, frames: list, errors: list, stop: threading.Event, after_frame=None) -> None:
    """A walk-through that moves its camera at every frame until ``stop``; counts its frames and errors."""
    walk = Walk(server)
    try:
        walk.send(type="hello", scene="tiny", width=W, height=H)
        k = 0
        while not stop.is_set():
            meta = walk.next(15)
            if meta["type"] == "error":
                errors.append(meta["message"])
                if "try again" in meta["message"]:
                    return
            elif meta["type"] == "frame":
                walk.ws.recv(15)
                frames.append(time.monotonic())
                k += 1
                walk.send(type="camera", eye=[0.2 * np.sin(k / 5), 1, 4], look_at=[0, 0.5, 0], id=k)
                if after_frame is not None:
                    after_frame(len(frames))
    finally:
        walk.close()


def test_walkers_are_admitted_while_there_is_room_and_none_starves(scenes, request):
    """The target is set so that the runtime's two cores hold three walkers at the measured cost: three walk
    at once, each gets its share of frames (painted on Ray); a fourth is painted on the server's own cores (room
    for one there), and a fifth is told in one line to come back."""
    with BackgroundServer(scenes=scenes, ray_address="local", walk_width=W, walk_height=H) as live:
        service = service_of(live.app)
        walks, driver = service.painter.walks, service.painter.cluster
        walks.local_room = 1
        params = service.scenes["tiny"].painting({})
        frame_s, ray_s = driver.call("cost")
        driver.call("target", 0.6 / (frame_s + W * H * params.spp * params.iterations * ray_s), W, H)
        assert driver.call("capacity", params) == 3  # 0.6 cores a walker at the cost measured
        stop = threading.Event()
        counts: list[list] = [[] for _ in range(5)]
        errors: list[list] = [[] for _ in range(5)]
        threads = [threading.Thread(target=walker, args=(live, counts[k], errors[k], stop)) for k in range(4)]
        request.addfinalizer(stop.set)  # a failure below stops the walkers too
        for thread in threads[:3]:
            thread.start()
        wait_until(lambda: len(walks.on_ray) >= 3)  # each walker placed on Ray
        threads[3].start()  # a fourth: painted here
        wait_until(lambda: counts[3])
        assert len(walks.on_ray) == 3 and len(walks.local) == 1
        fifth = Walk(live)  # a fifth: refused in one line, and its socket closed at once with the retry time
        fifth.send(type="hello", scene="tiny", width=W, height=H)
        refusal = fifth.next(30)
        assert refusal["type"] == "error"
        said = r"the cluster has room for 3 walkers at [\d.]+ fps at 96x64 \([\d.]+ cores each, measured\) and all"
        said += r" are walking, and the server's own cores hold 1 walkers, all walking; try again in 30 s"
        assert re.fullmatch(said, refusal["message"])
        with pytest.raises(ConnectionClosed) as closed:
            fifth.ws.recv(1.0)
        code, reason = closed.value.rcvd.code, closed.value.rcvd.reason
        assert code == 1013 and reason.endswith("; try again in 30 s") and len(reason.encode()) <= 123, reason
        fifth.close()
        wait_until(lambda: min(driver.call("figures")["painted"]) >= 5)  # each crew warm (painted here meanwhile)
        time.sleep(1.0)
        before, on_ray = [len(c) for c in counts[:4]], walks.frames
        time.sleep(4)
        got = [len(c) - n for c, n in zip(counts[:4], before, strict=True)]
        on_ray = walks.frames - on_ray
        stop.set()
        for thread in threads:
            thread.join(30)
        assert errors[:4] == [[], [], [], []]
        assert min(got) >= 5, got  # none starves beside the others
        assert on_ray >= 0.9 * sum(got[:3])  # the three painted on Ray (a crew member lost on a busy machine aside)


def _rays(args: list[bytes]) -> bool:
    """Whether a process is Ray's, by the program or script it runs: not a browser the session keeps open, nor
    the uploads' fork server (``python -c``, whose code lists a sys.path that holds Ray's own folders), nor the
    server's driver (``-m rcp_server.cluster.driver``)."""
    return args[1:2] not in ([b"-c"], [b"-m"]) and any(b"ray" in arg for arg in args[:3])


def descendants(pid: int) -> list[int]:
    """The processes ``pid`` started, and theirs."""
    import subprocess

    children = [
        int(k) for k in subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()
    ]
    return children + [d for k in children for d in descendants(k)]


def kill_rays(pid: int, which=_rays) -> int:
    """Kill (-9) the processes ``pid`` started (and theirs) that ``which`` picks by their command line."""
    killed = 0
    for child in descendants(pid):
        with contextlib.suppress(OSError):  # gone meanwhile
            if which(Path(f"/proc/{child}/cmdline").read_bytes().split(b"\0")):
                os.kill(child, signal.SIGKILL)
                killed += 1
    return killed


def walk_through_failure(live, request, fail, frames_after: int = 20, seconds: float = 60) -> list[float]:
    """A walker walks; ``fail()`` once it walked on Ray for a while; the frames' times after it."""
    service = service_of(live.app)
    failed: list[float] = []
    start = service.painter.walks.frames

    def after_frame(count: int) -> None:
        if not failed and service.painter.walks.frames > start + 5:
            fail()
            failed.append(time.monotonic())

    frames: list[float] = []
    errors: list[str] = []
    stop = threading.Event()
    thread = threading.Thread(target=walker, args=(live, frames, errors, stop, after_frame))
    thread.start()
    request.addfinalizer(stop.set)
    deadline = time.monotonic() + seconds
    while (not failed or len([t for t in frames if t > failed[0]]) < frames_after) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert failed, "the walker did not walk on Ray"
    assert get_json(f"{live.url}/api/health")["status"] == "ok"  # REST answers meanwhile
    stop.set()
    thread.join(30)
    assert errors == []  # no connection closed, no error said
    after = [t for t in frames if t > failed[0]]
    print(f"the walk paused {after[0] - failed[0]:.2f} s")
    assert len(after) >= frames_after and after[0] - failed[0] < 5.0
    return after


def test_a_crew_member_killed_mid_walk_leaves_and_the_walk_goes_on(scenes, request):
    with BackgroundServer(scenes=scenes, ray_address="local", walk_width=W, walk_height=H) as live:
        service = service_of(live.app)

        def kill() -> None:
            assert kill_rays(service.painter.cluster.pid, lambda args: args[0].startswith(b"ray::WalkPainter")) == 1

        walk_through_failure(live, request, kill, frames_after=5)
        assert service.painter.cluster.call("figures")["moved"] == 1


def test_the_raylet_killed_and_the_runtime_stopped_mid_walk_leave_the_server_painting(scenes, request):
    """The raylet killed: the driver ends, the server paints here, and goes back to Ray (a new driver, a runtime of
    its own) once it answers; then every process of that runtime killed, as ``ray stop --force`` does."""
    with BackgroundServer(scenes=scenes, ray_address="local", walk_width=W, walk_height=H) as live:
        service = service_of(live.app)
        driver = service.painter.cluster
        driver.backoff.first_s = 1.0
        first = driver.pid

        def raylet() -> None:
            assert kill_rays(driver.pid, lambda args: b"raylet" in args[0]) == 1

        walk_through_failure(live, request, raylet)
        wait_until(lambda: driver.ready() and driver.pid != first)  # asked, it starts a new driver on a new runtime
        on_ray = service.painter.walks.frames
        walk_through_failure(live, request, lambda: kill_rays(driver.pid))  # back on Ray first, then stopped
        assert service.painter.walks.frames > on_ray
        assert get_json(f"{live.url}/api/health")["status"] == "ok"
