"""Walk-throughs painted on a real local Ray runtime: the threads' frames pixel for pixel, the temporal state
kept on the worker and rebuilt after a loss, walkers admitted while there is room (one line past it) and none
starving, an actor killed mid-walk and the runtime stopped mid-walk without a connection closed.

One runtime for the module; the last test stops it."""

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

from service.conftest import Walk  # noqa: E402

from rcp_server.bench.harness import BackgroundServer  # noqa: E402
from rcp_server.cluster.admission import Target  # noqa: E402
from rcp_server.cluster.connection import Connection, connect  # noqa: E402
from rcp_server.cluster.walks import Walks  # noqa: E402
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
    worker (a frame sends the camera, not the state); killed, the actor is replaced within the frame's call and
    the recursion starts again from ``I_0`` there, then goes on from the new worker's own state."""
    walks = Walks(Connection(), Target(20, W, H), 30)
    first = PaintParams(iterations=3, lambda_p=6.0, lambda_e=0.05)
    step = replace(first, iterations=1)
    walks.calibrate(busy_scene, first)
    try:
        shots = cameras(busy_scene, 6)

        def on_ray(k: int, params: PaintParams, after: int | None):
            painted = walks.paint("w", busy_scene, shots[k], W, H, params, 0.1 * k, 80, k, after, keep_pixels=True)
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
        # the actor killed (a process gone, as a machine that goes down): the frame is painted by a new one
        os.kill(ray.get(walks.places["w"].actor.pid.remote()), signal.SIGKILL)
        clock = time.monotonic()
        painted = on_ray(3, step, 2)
        assert time.monotonic() - clock < 10 and walks.moved == 1
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


def test_walkers_are_admitted_while_there_is_room_and_none_starves(runtime, scenes, request):
    """The target is set so that the runtime's two cores hold three walkers at the measured cost: three walk
    at once, each gets its share of frames (painted on Ray), and a fourth is told in one line to come back."""
    with BackgroundServer(scenes=scenes, ray_address="local", walk_width=W, walk_height=H) as live:
        service = service_of(live.app)
        walks = service.painter.walks
        params = service.scenes["tiny"].painting({})
        frame_s = walks.cost.frame_cpu_s(W * H * params.spp * params.iterations)
        walks.target = Target(0.6 / frame_s, W, H)  # 0.6 cores a walker at the cost measured
        assert walks.capacity(params) == 3
        stop = threading.Event()
        counts: list[list] = [[] for _ in range(4)]
        errors: list[list] = [[] for _ in range(4)]
        threads = [threading.Thread(target=walker, args=(live, counts[k], errors[k], stop)) for k in range(3)]
        for thread in threads:
            thread.start()
        request.addfinalizer(stop.set)  # a failure below stops the walkers too
        deadline = time.monotonic() + 60
        while not all(counts[:3]) and time.monotonic() < deadline:  # each walker's actor started
            time.sleep(0.05)
        walker(live, counts[3], errors[3], threading.Event())  # a fourth: refused at once
        (refusal,) = errors[3]
        said = r"the cluster has room for \d walkers at [\d.]+ fps at 96x64 \([\d.]+ cores each, measured\) and all"
        assert re.fullmatch(said + r" are walking; try again in 30 s", refusal) and not counts[3]
        before, on_ray = [len(c) for c in counts[:3]], walks.frames
        time.sleep(4)
        got = [len(c) - n for c, n in zip(counts[:3], before, strict=True)]
        on_ray = walks.frames - on_ray
        stop.set()
        for thread in threads:
            thread.join(30)
        assert errors[:3] == [[], [], []]
        assert min(got) >= 10 and min(got) >= 0.4 * max(got), got  # none starves beside the others
        assert on_ray >= sum(got) - 3  # painted on Ray (frames in flight at either end aside)


def test_an_actor_killed_mid_walk_moves_and_the_walk_goes_on(runtime, scenes, request):
    with BackgroundServer(scenes=scenes, ray_address="local", walk_width=W, walk_height=H) as live:
        walks = service_of(live.app).painter.walks
        killed: list[float] = []

        def kill(count: int) -> None:
            if not killed and frames[-1] > frames[0] + 3:  # walking for a while: the spare actor is warm
                (place,) = walks.places.values()
                ray.kill(place.actor)  # no restart: a node gone
                killed.append(time.monotonic())

        frames: list[float] = []
        errors: list[str] = []
        stop = threading.Event()
        thread = threading.Thread(target=walker, args=(live, frames, errors, stop, kill))
        thread.start()
        request.addfinalizer(stop.set)
        deadline = time.monotonic() + 40
        while (not killed or len([t for t in frames if t > killed[0]]) < 5) and time.monotonic() < deadline:
            time.sleep(0.05)
        stop.set()
        thread.join(30)
        assert killed and errors == []
        after = [t for t in frames if t > killed[0]]
        print(f"the walk paused {after[0] - killed[0]:.2f} s")
        assert len(after) >= 5 and after[0] - killed[0] < 2.0  # a pause, then frames on the same connection
        assert walks.moved == 1


def _rays(args: list[bytes]) -> bool:
    """Whether a process is Ray's, by the program or script it runs: not a browser the session keeps open, nor
    the uploads' fork server (``python -c``, whose code lists a sys.path that holds Ray's own folders)."""
    return args[1:2] != [b"-c"] and any(b"ray" in arg for arg in args[:3])


def descendants(pid: int) -> list[int]:
    """The processes ``pid`` started, and theirs."""
    import subprocess

    children = [
        int(k) for k in subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()
    ]
    return children + [d for k in children for d in descendants(k)]


def test_the_runtime_killed_mid_walk_paints_here_and_no_connection_closes(runtime, scenes, request):
    """The last of the module: every process of the runtime is killed (-9), as a cluster lost as a whole."""
    with BackgroundServer(scenes=scenes, ray_address="local", walk_width=W, walk_height=H) as live:
        service = service_of(live.app)
        stopped: list[tuple[float, int]] = []

        def stop_ray(count: int) -> None:
            if not stopped and frames[-1] > frames[0] + 3:  # walking on Ray for a while
                for pid in descendants(os.getpid()):
                    with contextlib.suppress(OSError):  # gone meanwhile
                        if _rays(Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")):
                            os.kill(pid, signal.SIGKILL)
                stopped.append((time.monotonic(), service.painter.walks.frames))

        frames: list[float] = []
        errors: list[str] = []
        stop = threading.Event()
        thread = threading.Thread(target=walker, args=(live, frames, errors, stop, stop_ray))
        thread.start()
        request.addfinalizer(stop.set)
        deadline = time.monotonic() + 40
        while (not stopped or len([t for t in frames if t > stopped[0][0]]) < 20) and time.monotonic() < deadline:
            time.sleep(0.05)
        stop.set()
        thread.join(30)
        assert stopped and errors == []
        after = [t for t in frames if t > stopped[0][0]]
        print(f"the walk paused {after[0] - stopped[0][0]:.2f} s")
        assert len(after) >= 20 and after[0] - stopped[0][0] < 6.0
        assert (
            service.painter.walks.frames <= stopped[0][1] + 1
        )  # painted here meanwhile (one may have been on its way)
        assert not service.painter.cluster.ready()  # and Ray is tried again later, off the frames' path
