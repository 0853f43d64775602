"""A kernel compiled beside: on a cold numba cache, another process compiles it into the cache and this one
loads it from there; on a warm one, no process starts. Each case in a fresh interpreter of its own, on a cache
folder of its own."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import numpy as np
    from rcp_server.engine.kernels.embree import Hits
    from rcp_server.engine.kernels.jit import compile_beside
    from rcp_server.engine.kernels.triangle import place_hits

    triangles = np.array([[[0, 0, 1], [1, 0, 1], [0, 1, 1]]], np.float32)
    hits = Hits.misses(2)
    hits.face[:] = [0, -1]
    arguments = dict(
        origins=np.zeros((2, 3), np.float32),
        directions=np.array([[0.2, 0.2, 1], [0, 0, -1]], np.float32),
        rays=np.arange(2),
        triangles=triangles,
        hits=hits,
    )
    beside = compile_beside(place_hits, arguments)
    if beside is not None:
        beside.wait()
        assert beside.process.returncode == 0
    place_hits(**arguments)
    assert hits.t[0] == 1.0 and np.isclose(hits.b1[0], 0.2) and np.isclose(hits.b2[0], 0.2), hits
    print(beside is not None, sum(place_hits.stats.cache_hits.values()), sum(place_hits.stats.cache_misses.values()))
    """
)


def _run(cache) -> list[str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_a_cold_cache_compiles_the_kernel_beside_and_a_warm_one_starts_no_process(tmp_path):
    # cold: started beside, then loaded from the cache (a hit), never compiled here (no miss)
    assert _run(tmp_path) == ["True", "1", "0"]
    # warm: nothing to start, loaded from the cache
    assert _run(tmp_path) == ["False", "1", "0"]
