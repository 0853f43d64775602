"""Where each method breaks: screen edges, eye displacement, extremes, convergence, and a slow pan."""

import math
from dataclasses import replace

import numpy as np
import pytest
from helpers.scenes import CAMERA, make_scene

from rcp_server.bench.stability import (
    BROKEN,
    eye_section,
    flicker,
    grazing_scene,
    non_finite_section,
    pan,
    primary_directions,
    project,
    smudge_correlations,
    thin_poles_scene,
)
from rcp_server.camera.camera import Camera, CameraError, Region
from rcp_server.painting.assign import displacements, setup_tile
from rcp_server.painting.imagespace import bilinear, lookup_coords
from rcp_server.painting.loop import paint
from rcp_server.settings.mappings import MAPPINGS
from rcp_server.settings.params import EDGES, PaintParams

W, H = 48, 32


@pytest.mark.parametrize("edge", EDGES)
def test_image_method_differs_from_ray_tracing_only_where_lookups_leave_the_screen(gradient_scene, edge):
    params = PaintParams(iterations=2, lambda_p=6.0)
    traced = paint(gradient_scene, CAMERA, W, H, params).image.reshape(-1, 3)
    looked = paint(gradient_scene, CAMERA, W, H, replace(params, method="image", edge=edge)).image.reshape(-1, 3)
    plain = paint(gradient_scene, CAMERA, W, H, replace(params, iterations=1)).state
    region = Region(W, H)
    v_p, _ = displacements(plain, setup_tile(CAMERA, region, params), params, params.focus(CAMERA))
    x, y, _ = lookup_coords(v_p, CAMERA, region)
    off = (x < 0) | (x > W - 1) | (y < 0) | (y > H - 1)
    assert 0.05 < off.mean() < 0.5
    # on screen: what the ray sees (the plane is linear in x and y); off screen: the edge mode's pixel
    np.testing.assert_allclose(looked[~off], traced[~off], atol=2e-5)
    np.testing.assert_allclose(looked[off], bilinear(plain.image(), x[off], y[off], edge), atol=1e-6)
    wrong = np.abs(looked[off] - traced[off]).max(axis=1) > 1e-3
    assert wrong.mean() > 0.9  # the ray tracer saw the plane continue; no edge mode knows it


@pytest.mark.parametrize("method", ["raytrace", "image"])
@pytest.mark.parametrize("mapping", ["color", "depth", "normal"])
def test_huge_lambdas_keep_every_pixel_finite_and_in_range(busy_scene, method, mapping):
    params = PaintParams(mapping=mapping, method=method, iterations=3, lambda_p=1e6, noise=0.5)
    state = paint(busy_scene, CAMERA, W, H, params).state
    assert np.all(np.isfinite(state.color)) and np.all((state.color >= 0) & (state.color <= 1))


@pytest.mark.parametrize("method", ["raytrace", "image"])
def test_a_grazing_view_and_sub_pixel_geometry_stay_finite(method):
    for scene in (grazing_scene(), thin_poles_scene()):
        params = PaintParams(mapping="depth", method=method, iterations=3, lambda_p=2.0, z0=1.0)
        state = paint(scene, scene.camera, W, H, params).state
        assert np.all(np.isfinite(state.color)) and np.all(np.isfinite(state.depth))


@pytest.mark.parametrize(
    "eye,target,up",
    [((1, 2, 3), (1, 2, 3), (0, 1, 0)), ((0, 0, 0), (0, 4, 0), (0, 1, 0)), ((0, 0, 0), (0, 0, -1), (0, 0, 2))],
)
def test_degenerate_cameras_are_refused_before_painting(eye, target, up):
    with pytest.raises(CameraError):
        Camera(eye, target, up)


def test_eye_displacement_errs_most_near_silhouettes(busy_scene):
    measured = eye_section(busy_scene, W, H, PaintParams(iterations=3, lambda_p=3.0), 0.15)
    assert 0.05 < measured["near_silhouettes_fraction"] < 0.95
    assert measured["change_near_silhouettes"] > 1.5 * measured["change_elsewhere"]


@pytest.mark.parametrize("method", ["raytrace", "image"])
def test_convergence_on_a_smooth_plane_each_iteration_changes_less(gradient_scene, method):
    params = PaintParams(iterations=12, lambda_p=4.0, method=method)
    kept = paint(gradient_scene, CAMERA, W, H, params, keep_iterations=True).iterations
    inner = (slice(6, H - 6), slice(6, W - 6))
    changes = [np.abs(kept[n + 1] - kept[n])[inner].mean() for n in range(len(kept) - 1)]
    assert changes[0] > 1e-3
    assert all(b <= a * 1.0001 for a, b in zip(changes, changes[1:], strict=False))
    assert changes[-1] < 0.5 * changes[0]


def test_pan_keeps_the_eye_and_project_inverts_primary_rays():
    camera = Camera((1.0, 2.0, 3.0), (0.0, 1.5, -2.0), fov=50.0)
    turned = pan(camera, 3.0)
    assert turned.eye == camera.eye
    r, u, f = camera.basis()
    assert math.degrees(math.acos(np.clip(np.dot(f, turned.basis()[2]), -1, 1))) == pytest.approx(3.0)
    x, y = project(camera, W, H, primary_directions(camera, W, H))
    i, j = Region(W, H).pixel_coords()
    np.testing.assert_allclose(x, i, atol=1e-9)
    np.testing.assert_allclose(y, j, atol=1e-9)


def test_a_painting_that_moves_nothing_adds_no_flicker(busy_scene):
    cameras = [pan(CAMERA, 0.5 * k) for k in range(3)]
    plains = [paint(busy_scene, c, W, H, PaintParams(iterations=1)).image for c in cameras]
    still = [paint(busy_scene, c, W, H, PaintParams(lambda_p=0.0, method="image")).image for c in cameras]
    assert flicker(still, plains) == [0.0, 0.0]
    painted = [paint(busy_scene, c, W, H, PaintParams(lambda_p=5.0)).image for c in cameras]
    assert all(f != 0.0 for f in flicker(painted, plains))


@pytest.mark.parametrize("method", ["raytrace", "image"])
def test_smudges_stick_to_the_scene_not_to_the_screen(busy_scene, method):
    # a pan of 8 degrees moves the scene about 4 pixels on this 32-row screen
    scene = make_scene(busy_scene.objects, light=busy_scene.light, environment=busy_scene.environment)
    cameras = [pan(CAMERA, 4.0 * k) for k in range(3)]
    params = PaintParams(lambda_p=4.0, method=method)
    smudges = [
        paint(scene, c, W, H, params).image - paint(scene, c, W, H, PaintParams(iterations=1)).image for c in cameras
    ]
    with_scene, with_screen = smudge_correlations(smudges, cameras, lag=2)
    assert with_scene > 0.5 and with_scene > with_screen + 0.2
    fixed = [np.random.default_rng(3).normal(0, 0.1, (H, W, 3))] * 3  # a screen-space filter's pattern
    with_scene, with_screen = smudge_correlations(fixed, cameras, lag=2)
    assert with_screen == pytest.approx(1.0) and with_scene < 0.3


def test_the_broken_mapping_is_registered_only_while_its_section_paints(busy_scene):
    assert BROKEN not in MAPPINGS  # importing the benchmark registered nothing
    measured = non_finite_section(busy_scene, W, H, PaintParams(iterations=2, lambda_p=6.0))
    assert measured == {m: {"finite": True, "non_finite_pixels_kept_plain": True} for m in ("raytrace", "image")}
    assert BROKEN not in MAPPINGS
