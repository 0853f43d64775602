"""The walkers' scale model on given figures: walkers per node, the bounds of the server and the network, the
nodes a walker too large for one node takes, and one walker's frame in bands."""

from __future__ import annotations

import pytest

from rcp_server.bench.walkmodel import Measured, banded, nodes_per_walker, walker_cores, walkers_held

SIZE = (640, 360)
M = Measured(
    frame_s=0.005,
    ray_s=1e-7,
    overhead_s=0.004,
    server_s=0.002,
    jpeg_bytes={SIZE: 20_000},
    encode_s={SIZE: 0.01},
    iterations=6,
)


def test_walkers_a_cluster_holds_and_what_bounds_them():
    one = walker_cores(M, SIZE, 20, 1)  # 20 x (5 ms + 230,400 rays x 0.1 us) = 0.56 cores
    assert one == pytest.approx(20 * (0.005 + 0.02304))
    assert walkers_held(M, SIZE, 20, 1, nodes=4, cores=2, server_cores=4, gbps=10) == (4 * 3, "nodes", 1)
    # 4 server cores route 4 / (20 x 2 ms) = 100 walkers' frames: past that, the nodes wait for the server
    assert walkers_held(M, SIZE, 20, 1, nodes=64, cores=2, server_cores=4, gbps=10) == (100, "server", 1)
    assert walkers_held(M, SIZE, 20, 1, nodes=64, cores=2, server_cores=64, gbps=0.01)[1] == "network"


def test_a_walker_larger_than_a_node_takes_nodes_in_bands():
    assert walker_cores(M, SIZE, 20, 6) > 2  # six iterations a frame: about 2.9 cores
    span = nodes_per_walker(M, SIZE, 20, 6, cores=2)
    assert span == 2  # 2.76 core-s a second of rays over cores with 90% left each
    held, bound, nodes = walkers_held(M, SIZE, 20, 6, nodes=16, cores=2, server_cores=4, gbps=10)
    assert (held, nodes) == (8, 2) and bound == "nodes"


def test_one_walkers_frame_in_bands():
    fps, latency, bound = banded(M, SIZE, bands=16, iterations=6, gbps=10)
    paint = 0.005 + 640 * 360 * 6 * 1e-7 / 16
    server = 0.01 + 16 * 0.002
    assert bound == "server" and fps == pytest.approx(1 / server)
    assert latency == pytest.approx(0.004 + paint + 640 * 360 * 3 * 8 / 10e9 + server)


def test_bands_encoded_on_workers_leave_the_server_one_jpeg_a_frame():
    fps, latency, bound = banded(M, SIZE, bands=14, iterations=6, gbps=10, encoders=2)
    paint = 0.005 + 640 * 360 * 6 * 1e-7 / 14
    assert bound == "painting" and fps == pytest.approx(1 / paint)  # encoding 10 ms / 2 and routing 2 ms are less
    assert latency == pytest.approx(0.004 + paint + 640 * 360 * 3 * 8 / 10e9 + 0.01 + 0.002)


def test_a_crews_frame_takes_its_overhead_beside_its_share_of_the_rays():
    from rcp_server.bench.walkmodel import crew

    m = Measured(0.002, 1e-7, 0.004, 0.001, {(100, 100): 1000}, {(100, 100): 0.001}, 6)
    rate, latency, efficiency = crew(m, (100, 100), 4, 2, 6)
    rays_s = 100 * 100 * 6 * 1e-7 / 8  # a node's share of the rays, on its two cores
    assert latency == pytest.approx(0.004 + 0.002 + rays_s) and rate == pytest.approx(1 / latency)
    assert efficiency == pytest.approx(rays_s / latency)
    assert crew(m, (100, 100), 8, 2, 6)[2] < efficiency  # more nodes: quicker frames, each node less busy
