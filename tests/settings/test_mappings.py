"""Displacement mappings as fields: the formulas of shared/MISSION.md, registry and errors."""

import numpy as np
import pytest

from rcp_server.settings.mappings import (
    BUILT_IN,
    CHANNELS,
    MAPPINGS,
    MappingInput,
    get_mapping,
    register_mapping,
    unregister_mapping,
)


def _input(n=64, seed=0, z0=3.0):
    rng = np.random.default_rng(seed)
    r, u, f = np.eye(3)[[0, 1]].tolist() + [[0.0, 0.0, -1.0]]
    direction = rng.normal(size=(n, 3)).astype(np.float32)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    normal = rng.normal(size=(n, 3)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return MappingInput(
        color=rng.uniform(0, 1, (n, 3)).astype(np.float32),
        depth=rng.uniform(0.5, 10, n).astype(np.float32),
        normal=normal,
        direction=direction,
        right=np.tile(r, (n, 1)).astype(np.float64),
        up=np.tile(u, (n, 1)).astype(np.float64),
        forward=np.tile(f, (n, 1)).astype(np.float64),
        z0=z0,
        i=np.arange(n),
        j=np.zeros(n, int),
    )


def test_builtin_mappings_declare_what_they_read():
    assert get_mapping("color").reads == {"color"}
    assert get_mapping("depth").reads == {"color", "depth"}
    assert get_mapping("normal").reads == {"color", "normal", "direction"}
    assert all(m.reads <= set(CHANNELS) for m in MAPPINGS.values())


def test_color_field_formula():
    data = _input()
    basis = np.stack([data.right[0], data.up[0], data.forward[0]])
    expected = (2.0 * data.color.astype(np.float64) - 1.0) @ basis
    np.testing.assert_allclose(get_mapping("color").field(data), expected, rtol=0, atol=1e-6)
    mid = MappingInput(
        np.full((5, 3), 0.5, np.float32),
        None,
        None,
        None,
        data.right[:5],
        data.up[:5],
        data.forward[:5],
        1.0,
        np.arange(5),
        np.arange(5),
    )
    assert np.all(get_mapping("color").field(mid) == 0.0)


def test_depth_field_is_color_field_times_distance_from_focus():
    data = _input(z0=4.0)
    expected = (
        (2.0 * data.color.astype(np.float64) - 1.0)
        @ np.stack([data.right[0], data.up[0], data.forward[0]])
        * np.abs(data.depth.astype(np.float64) - 4.0)[:, None]
    )
    np.testing.assert_allclose(get_mapping("depth").field(data), expected, rtol=1e-5, atol=1e-5)


def test_depth_field_vanishes_exactly_at_the_focus_depth():
    data = _input(z0=2.5)
    focused = MappingInput(
        data.color,
        np.full(len(data.color), 2.5, np.float32),
        None,
        None,
        data.right,
        data.up,
        data.forward,
        2.5,
        data.i,
        data.j,
    )
    assert np.all(get_mapping("depth").field(focused) == 0.0)


def test_normal_field_is_direction_cross_normal_and_vanishes_when_parallel():
    data = _input()
    np.testing.assert_allclose(
        get_mapping("normal").field(data), np.cross(data.direction.astype(np.float64), data.normal), atol=1e-6
    )
    for normal in (-data.direction, data.direction):
        parallel = MappingInput(
            data.color,
            None,
            normal.astype(np.float32),
            data.direction,
            data.right,
            data.up,
            data.forward,
            1.0,
            data.i,
            data.j,
        )
        assert np.all(get_mapping("normal").field(parallel) == 0.0)


def test_unknown_mapping_error_lists_the_valid_ones():
    with pytest.raises(ValueError) as info:
        get_mapping("no-such-mapping")
    message = str(info.value)
    assert "no-such-mapping" in message
    for name in ("color", "depth", "normal"):
        assert name in message
    assert "\n" not in message


def test_register_mapping_adds_color_and_refuses_unknown_channels():
    @register_mapping("test-mappings-decorated", reads={"depth"})
    def decorated(data):
        """First line.

        More."""
        return np.zeros((len(data.color), 3))

    m = get_mapping("test-mappings-decorated")
    assert m.reads == {"color", "depth"} and m.field is decorated and m.description == "First line."
    register_mapping("test-mappings-direct", {"normal"}, lambda data: data.normal)
    assert get_mapping("test-mappings-direct").reads == {"color", "normal"}
    with pytest.raises(ValueError, match="roughness"):
        register_mapping("test-mappings-bad", {"roughness"}, lambda data: data.color)
    assert "test-mappings-bad" not in MAPPINGS


def test_unregister_mapping_forgets_a_registered_one_and_keeps_the_built_ins():
    register_mapping("test-mappings-passing", {"color"}, lambda data: data.color_field())
    unregister_mapping("test-mappings-passing")
    assert "test-mappings-passing" not in MAPPINGS
    with pytest.raises(ValueError, match="unknown mapping 'test-mappings-passing'"):
        unregister_mapping("test-mappings-passing")
    for name in BUILT_IN:
        with pytest.raises(ValueError, match="built in"):
            unregister_mapping(name)
    assert tuple(MAPPINGS)[: len(BUILT_IN)] == BUILT_IN
