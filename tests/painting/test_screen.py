"""The screen cells change no picture: every shipped scene, mapping, style, projection, stereo layout and tile
size paints the same bits with them on and off; the paintings they do not apply to (moving eyes, panoramas)
build none."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers.scenes import CAMERA, facing_plane, make_scene, sphere

from rcp_server.engine import kernels
from rcp_server.engine.kernels import screencells, visibility
from rcp_server.painting import assign
from rcp_server.painting.frame import Frame
from rcp_server.painting.loop import paint
from rcp_server.painting.workspace import pixel_bytes
from rcp_server.scene.scenefile import load_scene
from rcp_server.settings.mappings import BUILT_IN
from rcp_server.settings.params import PaintParams
from rcp_server.settings.styles import STYLES, with_style

SHIPPED = sorted(p.stem for p in (Path(__file__).resolve().parents[2] / "scenes").glob("*.toml"))


def _both(monkeypatch, scene, camera, width, height, params, threads=2):
    """The painting with the cells (built whatever it costs) and without them."""
    images = []
    for mode in ("on", "off"):
        monkeypatch.setenv(screencells.VARIABLE, mode)
        images.append(paint(scene, camera, width, height, params, threads=threads).image)
    return images


@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize(("width", "height", "threads"), [(96, 54, 2), (97, 55, 3), (61, 33, 1)])
def test_every_shipped_scene_paints_the_same_bits_with_the_cells_on_and_off(monkeypatch, name, width, height, threads):
    scene = load_scene(name)
    on, off = _both(monkeypatch, scene, scene.camera, width, height, scene.paint, threads)
    np.testing.assert_array_equal(on, off)


@pytest.mark.parametrize("look", [*(f"mapping {m}" for m in BUILT_IN), *(f"style {s}" for s in STYLES)])
def test_every_mapping_and_style_paints_the_same_bits_with_the_cells_on_and_off(monkeypatch, look):
    scene = load_scene("default")
    kind, name = look.split(" ", 1)
    params = replace(scene.paint, mapping=name) if kind == "mapping" else with_style(scene.paint, {"style": name})
    on, off = _both(monkeypatch, scene, scene.camera, 80, 45, params)
    np.testing.assert_array_equal(on, off)


@pytest.mark.parametrize("stereo", ["top-bottom", "side-by-side"])
def test_a_stereo_painting_paints_the_same_bits_with_each_eye_its_own_cells(monkeypatch, stereo):
    scene = load_scene("default")
    camera = scene.camera.moved(stereo=stereo, ipd=0.2)
    width, height = (80, 90) if stereo == "top-bottom" else (160, 45)
    on, off = _both(monkeypatch, scene, camera, width, height, scene.paint)
    np.testing.assert_array_equal(on, off)
    monkeypatch.setenv(screencells.VARIABLE, "on")
    frame = Frame.of(scene, 0.0, camera, scene.paint, width, height)
    assert frame.trace.screen.on and frame.trace.screen.eyes.shape == (2, 3)


def _fine_scene():
    return make_scene([sphere(subdivisions=3), facing_plane(8.0, divisions=(30, 30), color=(0.3, 0.6, 0.9))])


def test_a_fine_mesh_paints_the_same_bits_and_most_rays_are_answered_by_the_cells(monkeypatch):
    scene, params = _fine_scene(), PaintParams(lambda_p=6.0, iterations=3)
    on, off = _both(monkeypatch, scene, CAMERA, 320, 180, params)
    np.testing.assert_array_equal(on, off)
    monkeypatch.setenv(screencells.VARIABLE, "on")
    frame = Frame.of(scene, 0.0, CAMERA, params, 320, 180)
    counts = _paths(frame, CAMERA, params, 320, 180)
    assert counts[visibility.ANSWERED] > 0.6 * counts.sum()


def _paths(frame, camera, params, width, height):
    """Which path each ray of the first iteration takes (visibility.REASONS)."""
    from rcp_server.camera.camera import Region
    from rcp_server.engine.paintstate import PaintState

    region = Region(width, height)
    setup = assign.setup_tile(camera, region, params)
    rays = assign.Rays.allocate(region.pixel_count, params.spp)
    assign.assign_cameras(PaintState.canvas(region), setup, params, params.focus(camera), rays)
    counts = np.zeros(len(visibility.REASONS), np.int64)
    visibility.reasons(frame.trace.screen, rays.origins, rays.directions, np.arange(len(rays.origins)), counts)
    return counts


@pytest.mark.parametrize("case", ["moving eye", "panorama", "switched off"])
def test_moving_eyes_and_panoramas_go_to_embree(monkeypatch, case):
    monkeypatch.setenv(screencells.VARIABLE, "off" if case == "switched off" else "on")
    scene, params, camera, width, height = _fine_scene(), PaintParams(lambda_p=6.0, iterations=2), CAMERA, 96, 54
    if case == "moving eye":
        params = replace(params, lambda_e=0.05)
    if case == "panorama":
        camera, width, height = CAMERA.moved(projection="equirect"), 96, 48
    frame = Frame.of(scene, 0.0, camera, params, width, height)
    assert frame.trace.screen is kernels.NO_SCREEN
    counts = _paths(frame, camera, params, width, height)
    assert counts[visibility.ANSWERED] == 0 and counts.sum() == width * height
    on, off = _both(monkeypatch, scene, camera, width, height, params)
    np.testing.assert_array_equal(on, off)


def test_auto_builds_the_cells_only_for_paintings_that_cast_enough_rays_a_triangle(monkeypatch):
    monkeypatch.setenv(screencells.VARIABLE, "auto")
    scene, params = _fine_scene(), PaintParams(iterations=6)
    faces = scene.geometry(0.0)[0].face_count
    small = Frame.of(scene, 0.0, CAMERA, params, 64, 36)
    large = Frame.of(scene, 0.0, CAMERA, params, 320, 180)
    assert 64 * 36 * 6 < screencells.PAYS * faces <= 320 * 180 * 6
    assert not small.trace.screen.on and large.trace.screen.on
    monkeypatch.delenv(screencells.VARIABLE)
    assert screencells.mode() == "auto"
    monkeypatch.setenv(screencells.VARIABLE, "off")
    assert not Frame.of(scene, 0.0, CAMERA, params, 320, 180).trace.screen.on
    monkeypatch.setenv(screencells.VARIABLE, "sometimes")
    with pytest.raises(ValueError, match="RCP_SCREEN_CELLS"):
        screencells.mode()


def test_auto_drops_the_cells_where_crowded_triangles_would_send_their_rays_to_embree_anyway(monkeypatch):
    # a fine sphere far off: more than LONGEST triangles a cell wherever it is seen, no cell answers it
    far = sphere(center=(0.0, 0.0, -12.0), radius=0.8, subdivisions=5)
    scene, params = make_scene([far]), PaintParams(iterations=6, spp=4)
    faces = scene.geometry(0.0)[0].face_count
    assert 320 * 180 * 6 * 4 >= screencells.PAYS * faces
    monkeypatch.setenv(screencells.VARIABLE, "on")
    built = Frame.of(scene, 0.0, CAMERA, params, 320, 180).trace.screen
    assert built.on and not screencells.answers(built)
    monkeypatch.setenv(screencells.VARIABLE, "auto")
    assert not Frame.of(scene, 0.0, CAMERA, params, 320, 180).trace.screen.on
    on, off = _both(monkeypatch, scene, CAMERA, 64, 36, params)
    np.testing.assert_array_equal(on, off)


def test_the_cells_take_no_more_bytes_than_declared(monkeypatch):
    monkeypatch.setenv(screencells.VARIABLE, "on")
    scene = load_scene("default")
    for params in (scene.paint, replace(scene.paint, lambda_p=1000.0)):
        frame = Frame.of(scene, 0.0, scene.camera, params, 320, 180)
        assert 0 < frame.trace.screen.nbytes() <= pixel_bytes(params)["screen"] * 320 * 180
