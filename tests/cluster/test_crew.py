"""One walker's frame in bands over a crew, on Ray's multi-node test cluster (three nodes of one CPU, each its own
raylet), through the driver in its child process as the server calls it: bands on distinct nodes, pixel for pixel
the threads' frames; a node removed mid-walk (the crew shrinks, frames go on); the whole cluster stopped (painted
here meanwhile, back on Ray once it is up again). One cluster for the module; the last test stops it."""

from __future__ import annotations

import itertools
import socket
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

ray = pytest.importorskip("ray")  # the cluster extra; the test extra installs it

from helpers.waits import WAIT_S, wait_until  # noqa: E402
from ray.cluster_utils import Cluster  # noqa: E402

from rcp_server.cluster.admission import Target  # noqa: E402
from rcp_server.cluster.remote import RemoteRay, RemoteWalks  # noqa: E402
from rcp_server.cluster.walks import NoRoom  # noqa: E402
from rcp_server.painting.loop import paint  # noqa: E402
from rcp_server.scene.scene import Scene  # noqa: E402
from rcp_server.settings.params import PaintParams  # noqa: E402
from rcp_server.util import images  # noqa: E402

W, H = 128, 96  # frames whose painting outweighs a call's overhead: three nodes help
NODES = 3


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Nodes:
    """The test cluster, started again on the same port after it was stopped."""

    def __init__(self) -> None:
        self.port = free_port()
        self.cluster: Cluster | None = None

    def start(self) -> None:
        head = {
            "num_cpus": 1,
            "gcs_server_port": self.port,
            "include_dashboard": False,
            "object_store_memory": 80 << 20,
        }
        self.cluster = Cluster(initialize_head=True, head_node_args=head, connect=False)
        for _ in range(NODES - 1):
            self.cluster.add_node(num_cpus=1, object_store_memory=80 << 20)

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def stop(self) -> None:
        if self.cluster is not None:
            self.cluster.shutdown()
            self.cluster = None


@pytest.fixture(scope="module")
def nodes():
    started = Nodes()
    started.start()
    yield started
    started.stop()


@pytest.fixture(scope="module")
def walks(nodes, busy_scene):
    driver = RemoteRay(nodes.address, Target(20, W, H), 30)
    driver.start(120)
    walks = RemoteWalks(driver, 1, 30)
    walks.calibrate(busy_scene, PaintParams(iterations=2))
    driver.call("target", 0.01, W, H)  # a target every node holds many of: room is not what this module tests
    yield walks
    walks.close()
    driver.close()


def on_ray(walks: RemoteWalks, scene: Scene, k: int, params: PaintParams, after: int | None, bands: int = NODES):
    """Frame ``k`` painted on Ray once the walker's crew has ``bands`` warm members (0: any; painted here
    meanwhile)."""
    deadline = time.monotonic() + 60
    while True:
        try:
            painted = walks.paint("w", scene, camera(scene, k), W, H, params, 0.1 * k, 80, k, after, keep_pixels=True)
        except NoRoom:
            painted = None
        if painted is not None and (len(painted.bands) == bands or bands == 0):
            return painted
        assert time.monotonic() < deadline, "the crew did not start"
        time.sleep(0.1)


def live_groups(walks: RemoteWalks) -> dict:
    """Ray's placement groups not removed, from its own table (asked through the driver)."""
    return {gid: g for gid, g in walks.ray.call("groups", timeout_s=10.0).items() if g["state"] != "REMOVED"}


def settled(walks: RemoteWalks, scene: Scene, params: PaintParams, bands: int) -> dict:
    """The walker's one placement group, once its ``bands`` members all live in it (frames painted meanwhile: a crew
    moves into a new group between frames)."""
    frames = itertools.count(1000)

    def groups() -> tuple[list[dict], list[str]]:
        painted = on_ray(walks, scene, next(frames), params, None, bands=bands)
        return list(live_groups(walks).values()), sorted(b.node for b in painted.bands)

    found, nodes = wait_until(groups, lambda seen: len(seen[0]) == 1 and sorted(seen[0][0]["nodes"]) == seen[1])
    return found[0]


def camera(scene: Scene, k: int):
    return scene.camera.moved(eye=(0.3 * k, 0.2, 0.1 * k))


def threads(scene: Scene, k: int, params: PaintParams, previous=None):
    return paint(scene, camera(scene, k), W, H, params, time=0.1 * k, previous=previous, threads=2)


def test_a_walkers_frame_is_painted_in_bands_on_distinct_nodes_pixel_for_pixel_the_threads(walks, busy_scene):
    first = PaintParams(iterations=4, spp=4, lambda_p=6.0, lambda_e=0.05)
    step = replace(first, iterations=3)
    walks.admit("w", first, busy_scene)
    group = settled(walks, busy_scene, first, NODES)  # through the walker's placement group: a bundle a band's node
    assert group["strategy"] == "STRICT_SPREAD" and len(set(group["nodes"])) == NODES
    painted = on_ray(walks, busy_scene, 0, first, None)
    assert len({band.node for band in painted.bands}) == NODES  # one band a node
    assert sorted(group["nodes"]) == sorted(b.node for b in painted.bands)
    assert list(live_groups(walks).values()) == [group]
    assert [(b.y, b.rows) for b in painted.bands] == [(0, 32), (32, 32), (64, 32)]
    for band in painted.bands:  # each band encoded on its worker, small enough for Ray's reply
        assert band.jpeg[:2] == b"\xff\xd8" and len(band.jpeg) < 100 << 10
    np.testing.assert_array_equal(painted.pixels, images.to_uint8(threads(busy_scene, 0, first).image))
    assert not painted.continued
    # temporal: each band goes on from the state its own worker keeps
    state = threads(busy_scene, 0, first).state
    for k in (1, 2):
        expected = threads(busy_scene, k, step, state)
        painted = on_ray(walks, busy_scene, k, step, k - 1)
        assert painted.continued
        np.testing.assert_array_equal(painted.pixels, images.to_uint8(expected.image))
        state = expected.state


def test_a_walker_that_changes_scene_and_back_is_painted_as_the_threads_paint_each(walks, busy_scene, gradient_scene):
    """A band call sends the scene only when the member's last scene was another: the new scene, then the old
    one again (which the worker still holds built), each painted as the threads paint it."""
    params = PaintParams(iterations=2, spp=1, lambda_p=4.0)
    walks.admit("w", params, busy_scene)
    for k, scene in enumerate((gradient_scene, busy_scene, busy_scene), start=3):
        painted = on_ray(walks, scene, k, params, None)
        expected = paint(scene, camera(scene, k), W, H, params, time=0.1 * k, threads=2)
        np.testing.assert_array_equal(painted.pixels, images.to_uint8(expected.image))


def test_a_node_removed_mid_walk_shrinks_the_crew_and_the_frames_go_on(walks, nodes, busy_scene):
    params = PaintParams(iterations=4, spp=4)
    walks.admit("w", params, busy_scene)
    on_ray(walks, busy_scene, 10, params, None)
    assert nodes.cluster is not None
    gone = next(iter(nodes.cluster.worker_nodes))
    frames: list[tuple[float, int]] = []
    removed: list[float] = []

    def walk() -> None:
        for k in range(11, 200):
            try:
                painted = walks.paint("w", busy_scene, camera(busy_scene, k), W, H, params, 0.0, 80, k, None)
                frames.append((time.monotonic(), len(painted.bands)))
            except NoRoom:
                time.sleep(0.05)
            if removed and len([f for f in frames if f[0] > removed[0] and f[1] == NODES - 1]) >= 5:
                return

    walker = threading.Thread(target=walk)
    walker.start()
    wait_until(lambda: len(frames) >= 3)
    nodes.cluster.remove_node(gone, allow_graceful=False)
    removed.append(time.monotonic())
    walker.join(WAIT_S)
    assert not walker.is_alive()
    after = [t for t, _ in frames if t > removed[0]]
    pauses = np.diff([removed[0], *after])
    print(f"the walk paused at most {pauses.max():.2f} s", [(round(t - removed[0], 2), n) for t, n in frames])
    # the frames went on: the walk ended by itself, within the frames it had, on five frames of the crew shrunk
    # to the nodes left
    assert [n for _, n in frames[-5:]] == [NODES - 1] * 5
    # meanwhile the walker's group is rebuilt for the nodes left, its members move into it, the old one goes
    group = settled(walks, busy_scene, params, NODES - 1)
    assert gone.node_id not in group["nodes"]


def test_a_walker_that_leaves_removes_its_placement_group(walks, busy_scene):
    params = PaintParams(iterations=2)
    walks.admit("w", params, busy_scene)
    assert live_groups(walks)
    walks.leave("w")
    wait_until(lambda: live_groups(walks), lambda groups: not groups)


def test_the_whole_cluster_stopped_paints_here_and_returns_to_ray_once_it_is_back(walks, nodes, busy_scene):
    """The last of the module: the cluster stopped as a whole, then started again on the same port."""
    params = PaintParams(iterations=4, spp=4)
    walks.admit("w", params, busy_scene)
    walks.ray.backoff.first_s, walks.ray.backoff.most_s = 1.0, 2.0
    generation = walks.ray.generation
    nodes.stop()
    wait_until(lambda: walks.ray.generation != generation or not walks.ray.ready())  # the driver ends with its raylet
    with pytest.raises(NoRoom):  # painted here meanwhile: at once, not after a wait on Ray
        walks.paint("w", busy_scene, busy_scene.camera, W, H, params, 0.0, 80, 100, None)
    nodes.start()
    painted = on_ray(walks, busy_scene, 101, params, None, bands=0)  # back on Ray, its crew growing again
    assert walks.ray.generation > generation
    assert all(jpeg[:2] == b"\xff\xd8" for jpeg in [painted.jpeg, *(b.jpeg for b in painted.bands)] if jpeg)
