"""How many walkers a KubeRay cluster holds, and how one walker's frame splits in bands: a model on measured
figures (``rcp bench cluster`` measures them on Ray and prints the model; no figure here is assumed but the
network and the server's cores, which are the command's flags).

A walker at ``fps`` frames a second of ``size`` pixels takes ``fps * (frame_s + pixels * iterations * ray_s)``
cores of its node (:class:`Measured`: a frame's fixed CPU on a worker, and a ray's); a node of ``cores`` cores
holds the whole walkers that fit. The server routes every frame: it spends ``server_s`` of CPU on each and sends
its JPEG, so ``server_cores / (fps * server_s)`` and ``link / (fps * bytes)`` bound the walkers of the whole
cluster. One walker's frame in bands: each of ``bands`` cores paints its rows (a band's fixed CPU, and its
share of the rays), the server gathers the raw rows (3 bytes a pixel) and encodes the JPEG itself; a frame
then takes the slowest of painting a band, moving the rows and encoding, with two frames in flight hiding the
round trip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Measured:
    """Figures measured on Ray, for one scene and its settings.

    frame_s : CPU seconds a worker spends on any frame (the call, the encoder's start, Ray's threads);
    ray_s : CPU seconds a worker spends on a ray (a pixel's sample through one iteration); overhead_s : a
    frame's round trip on Ray beyond its painting (wall seconds); server_s : CPU seconds the server spends on
    a frame it routes; jpeg_bytes : size -> bytes of a walk frame's JPEG; encode_s : size -> seconds the server
    takes to encode a frame (for bands); iterations : a walk frame's, per frame (all) and temporal (1)."""

    frame_s: float
    ray_s: float
    overhead_s: float
    server_s: float
    jpeg_bytes: dict[tuple[int, int], int]
    encode_s: dict[tuple[int, int], float]
    iterations: int


def walker_cores(m: Measured, size: tuple[int, int], fps: float, iterations: int) -> float:
    """Cores one walker takes at ``fps`` frames of ``size`` with ``iterations`` a frame (1 sample a pixel)."""
    return fps * (m.frame_s + size[0] * size[1] * iterations * m.ray_s)


def nodes_per_walker(m: Measured, size: tuple[int, int], fps: float, iterations: int, cores: int) -> int | None:
    """Nodes one walker's frames take: 1 when a walker fits a node, else the fewest whose cores paint its frame
    in bands (a band a core, each with its fixed CPU); None when no number of nodes keeps up."""
    if walker_cores(m, size, fps, iterations) <= cores:
        return 1
    rays_s = fps * size[0] * size[1] * iterations * m.ray_s  # core-seconds a second of the rays alone
    spare = 1 - fps * m.frame_s  # what a core has left for rays once it paid each band's fixed part
    return math.ceil(rays_s / (spare * cores)) if spare > 0 else None


def walkers_held(
    m: Measured, size: tuple[int, int], fps: float, iterations: int, nodes: int, cores: int, server_cores: int, gbps
) -> tuple[int, str, int]:
    """Walkers ``nodes`` nodes of ``cores`` cores hold, what bounds them ('nodes', 'server' or 'network'), and the
    nodes each walker's frames take (more than 1: in bands, the server gathering a band a core)."""
    span = nodes_per_walker(m, size, fps, iterations, cores)
    if span is None:
        return 0, "nodes", 0
    per_node = math.floor(cores / walker_cores(m, size, fps, iterations) + 1e-9) if span == 1 else 0
    bands = 1 if span == 1 else span * cores
    server_s = m.server_s * bands + (m.encode_s[size] if bands > 1 else 0.0)
    bounds = {
        "nodes": nodes * per_node if span == 1 else nodes // span,
        "server": math.floor(server_cores / (fps * server_s)),
        "network": math.floor(gbps * 1e9 / 8 / (fps * (m.jpeg_bytes[size] if bands == 1 else size[0] * size[1] * 3))),
    }
    which = min(bounds, key=lambda k: bounds[k])
    return bounds[which], which, span


def banded(
    m: Measured, size: tuple[int, int], bands: int, iterations: int, gbps: float, encoders: int = 0
) -> tuple[float, float, str]:
    """One walker's frame of ``size`` in ``bands`` bands, a core each: (frames a second, the latency of a
    frame in seconds, what bounds the rate: 'painting', 'network', 'server' or 'encoding'). Without
    ``encoders`` the server gathers the bands and encodes; with them, ``encoders`` worker cores gather and encode
    a frame each in turn (frames in flight), and the server routes one JPEG a frame."""
    paint_s = m.frame_s + size[0] * size[1] * iterations * m.ray_s / bands
    move_s = size[0] * size[1] * 3 * 8 / (gbps * 1e9)
    if encoders:
        steps = {"painting": paint_s, "network": move_s, "server": m.server_s, "encoding": m.encode_s[size] / encoders}
        latency = m.overhead_s + paint_s + move_s + m.encode_s[size] + m.server_s
        which = max(steps, key=lambda k: steps[k])
        return 1 / steps[which], latency, which
    server_s = m.encode_s[size] + bands * m.server_s  # the server receives every band, then encodes
    steps = {"painting": paint_s, "network": move_s, "server": server_s}
    which = max(steps, key=lambda k: steps[k])
    return 1 / steps[which], m.overhead_s + paint_s + move_s + server_s, which


def crew(m: Measured, size: tuple[int, int], nodes: int, cores: int, iterations: int) -> tuple[float, float, float]:
    """One walker's frame of ``size`` in a band a node over ``nodes`` nodes of ``cores`` cores, each band painted
    with its node's threads and encoded there, the server forwarding the bands as they are: one call per node per
    frame, one frame in flight. Returns (frames a second, the latency of a frame in seconds, the per-node
    efficiency: the frame's rays alone over ``nodes x cores`` against the frame's whole time)."""
    rays_s = size[0] * size[1] * iterations * m.ray_s / (nodes * cores)
    period = m.overhead_s + m.frame_s + rays_s
    return 1 / period, period, rays_s / period
