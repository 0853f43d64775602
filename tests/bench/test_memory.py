"""``rcp bench memory`` measures a scene in a fresh process: what it adds loaded, and its peak once painted."""

from __future__ import annotations

from helpers.scenes import SPINNING_BOX

from rcp_server.bench.memory import measure


def test_a_scene_is_measured_in_a_process_of_its_own(tmp_path):
    path = tmp_path / "box.toml"
    path.write_text(SPINNING_BOX)
    m = measure(str(path), 64, 48, 1)
    assert m["triangles"] == 12 and m["textures"] == 0
    assert m["base"] > 50 << 20  # the interpreter with the engine imported
    assert 0 <= m["loaded"] <= m["peak"]  # the peak includes what loading left resident
    assert 0 < m["loaded_s"] <= m["first_frame_s"]
