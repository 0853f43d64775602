"""The fixtures every test may use: its own data folder, and the tiny scenes of ``helpers/scenes.py`` as
session fixtures. Helpers that are not fixtures live in ``tests/helpers/``."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.browser import SOFTWARE_WEBGL, chromium
from helpers.scenes import facing_plane, gradient, make_scene, sphere
from helpers.servers import BackgroundServer

from rcp_server.scene.scene import Environment, Light, Scene


@pytest.fixture(scope="session", autouse=True)
def _own_data_folder(tmp_path_factory):
    """``RCP_DATA`` in a temporary folder for the whole session: no test touches the user's data folder (servers
    started by tests get one of their own besides: ``helpers/servers.py``)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("RCP_DATA", str(tmp_path_factory.mktemp("rcp-data")))
        yield


@pytest.fixture(scope="session")
def gradient_scene() -> Scene:
    """An unlit plane at depth 4 whose albedo is linear in x and y; it fills the standard view."""
    return make_scene([facing_plane(4.0, colors_of=gradient)])


@pytest.fixture(scope="session")
def busy_scene() -> Scene:
    """Lit, textured and colored objects at several depths in front of a gradient sky: every mapping moves."""
    rng = np.random.default_rng(0)
    texture = rng.uniform(0, 1, (8, 8, 3)).astype(np.float32)
    sky = np.stack([*np.meshgrid(np.linspace(0, 1, 32), np.linspace(0, 1, 16)), np.full((16, 32), 0.3)], axis=2).astype(
        np.float32
    )
    objects = [
        facing_plane(9.0, size=(10.0, 6.0), divisions=(3, 2), texture=texture, center=(0.0, -2.0)),
        sphere((-1.2, 0.3, -4.5), 1.0, 2, (0.9, 0.2, 0.1), "red"),
        sphere((1.5, -0.4, -6.0), 1.3, 2, (0.1, 0.8, 0.3), "green"),
        sphere((0.4, 1.2, -3.0), 0.4, 1, (0.2, 0.3, 0.95), "blue"),
    ]
    light = Light(tuple(np.array([-0.3, -1.0, -0.4]) / np.linalg.norm([-0.3, -1.0, -0.4])), 0.3)
    return make_scene(objects, light=light, environment=Environment(sky))


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium (``helpers/browser.py``), one a test module."""
    with chromium() as launched:
        yield launched


@pytest.fixture(scope="module")
def webgl_browser():
    """A headless Chromium drawing WebGL in software (SwiftShader): the same pixels on every machine."""
    with chromium(*SOFTWARE_WEBGL) as launched:
        yield launched


@pytest.fixture(scope="session")
def live_server():
    """One real server per test process (settles fast, so refinement starts soon after the camera rests)."""
    with BackgroundServer(settle_ms=80) as server:
        yield server
