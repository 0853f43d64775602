"""Camera conventions of shared/MISSION.md: basis, image plane, pixel pitch, validation, regions."""

import math

import numpy as np
import pytest

from rcp_server.camera.camera import Camera, CameraError, Region, directions_at


def test_basis_follows_mission_formulas():
    eye, look_at, up = np.array([1.0, 2.0, 3.0]), np.array([-2.0, 0.5, -4.0]), np.array([0.1, 1.0, 0.2])
    r, u, f = Camera(tuple(eye), tuple(look_at), tuple(up)).basis()
    f_ref = (look_at - eye) / np.linalg.norm(look_at - eye)
    r_ref = np.cross(f_ref, up) / np.linalg.norm(np.cross(f_ref, up))
    u_ref = np.cross(r_ref, f_ref)
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-15)
    np.testing.assert_allclose(r, r_ref, rtol=0, atol=1e-15)
    np.testing.assert_allclose(u, u_ref, rtol=0, atol=1e-15)
    # orthonormal and right-handed: r x u = -f (f points into the screen, r right, u up)
    np.testing.assert_allclose(np.stack([r, u, f]) @ np.stack([r, u, f]).T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(np.cross(r, u), -f, atol=1e-14)


def test_default_camera_looking_down_minus_z_has_x_right_y_up():
    cam = Camera((0, 0, 0), (0, 0, -1))
    assert cam.up == (0.0, 1.0, 0.0) and cam.fov == 60.0
    r, u, f = cam.basis()
    np.testing.assert_array_equal(r, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(u, [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(f, [0.0, 0.0, -1.0])


def plane_points(camera, region, s, t):
    """``P_p(s, t)`` of a mono camera: its eye plus the forward map's offset at ``(s W, t H)``."""
    return np.asarray(camera.eye) + directions_at(camera, region, s * region.full_width, t * region.full_height)[0]


def test_plane_points_formula_and_corners():
    cam = Camera((0.5, -1.0, 2.0), (3.0, 1.0, -1.0), (0.0, 1.0, 0.3), fov=47.0)
    region = Region(40, 25)
    rng = np.random.default_rng(1)
    s, t = rng.uniform(0, 1, 50), rng.uniform(0, 1, 50)
    r, u, f = cam.basis()
    tan_half = math.tan(math.radians(47.0) / 2)
    a = 40 / 25
    expected = (
        np.asarray(cam.eye) + f + ((2 * s - 1) * a * tan_half)[:, None] * r + ((1 - 2 * t) * tan_half)[:, None] * u
    )
    np.testing.assert_allclose(plane_points(cam, region, s, t), expected, rtol=0, atol=1e-13)
    # (s, t) = (0, 0) is the top-left corner: left of centre along r, above along u
    top_left = plane_points(cam, region, np.array([0.0]), np.array([0.0]))[0]
    np.testing.assert_allclose(top_left, np.asarray(cam.eye) + f - a * tan_half * r + tan_half * u, atol=1e-13)
    centre = plane_points(cam, region, np.array([0.5]), np.array([0.5]))[0]
    np.testing.assert_allclose(centre, np.asarray(cam.eye) + f, atol=1e-15)


def test_plane_points_use_the_full_image_aspect_for_a_region():
    cam = Camera((0, 0, 0), (0, 0, -1), fov=60)
    full = plane_points(cam, Region(64, 32), np.array([0.25]), np.array([0.75]))
    part = plane_points(cam, Region(64, 32, 10, 5, 8, 4), np.array([0.25]), np.array([0.75]))
    np.testing.assert_array_equal(full, part)


@pytest.mark.parametrize("width,height", [(32, 24), (17, 41)])
def test_pixel_pitch_is_the_distance_between_neighbouring_pixel_centres(width, height):
    cam = Camera((1, 2, 3), (0, 0, 0), fov=35.0)
    p = cam.pixel_pitch(height)
    assert p == pytest.approx(2 * math.tan(math.radians(35.0) / 2) / height, rel=1e-15)
    region = Region(width, height)
    i = np.array([3, 4, 3])
    j = np.array([5, 5, 6])
    pts = plane_points(cam, region, (i + 0.5) / width, (j + 0.5) / height)
    r, u, _ = cam.basis()
    # one column to the right is p along r, one row down is p along -u: square pixels
    np.testing.assert_allclose(pts[1] - pts[0], p * r, rtol=0, atol=1e-14)
    np.testing.assert_allclose(pts[2] - pts[0], -p * u, rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"eye": (1, 2, 3), "look_at": (1, 2, 3)},
        {"eye": (0, 0, 0), "look_at": (0, 5, 0)},  # up parallel to the view
        {"eye": (0, 0, 0), "look_at": (0, -5, 0)},  # up anti-parallel to the view
        {"eye": (0, 0, 0), "look_at": (1, 0, 0), "up": (2, 0, 0)},
        {"eye": (0, 0, 0), "look_at": (1, 0, 0), "up": (0, 0, 0)},
        {"eye": (float("nan"), 0, 0), "look_at": (1, 0, 0)},
        {"eye": (0, 0, 0), "look_at": (1, float("inf"), 0)},
        {"eye": (0, 0, 0), "look_at": (1, 0, 0), "up": (0, float("nan"), 0)},
        {"eye": (0, 0, 0), "look_at": (1, 0, 0), "fov": float("nan")},
        {"eye": (0, 0, 0), "look_at": (1, 0, 0), "fov": 0.0},
        {"eye": (0, 0, 0), "look_at": (1, 0, 0), "fov": 180.0},
        {"eye": (0, 0), "look_at": (1, 0, 0)},
    ],
)
def test_degenerate_cameras_raise_camera_error(kwargs):
    with pytest.raises(CameraError):
        Camera(**kwargs)


def test_camera_error_is_a_value_error_and_moved_revalidates():
    assert issubclass(CameraError, ValueError)
    cam = Camera((0, 0, 5), (0, 0, 0))
    assert cam.moved(fov=30).fov == 30.0 and cam.moved(fov=30).eye == cam.eye
    with pytest.raises(CameraError):
        cam.moved(look_at=(0, 0, 5))


@pytest.mark.parametrize(
    "region,rows",
    [
        (Region(13, 11), 3),
        (Region(13, 11), 11),
        (Region(13, 11), 100),
        (Region(40, 30, 7, 4, 9, 17), 5),
        (Region(40, 30, 7, 4, 9, 17), 1),
    ],
)
def test_region_tiles_cover_the_region_exactly_once(region, rows):
    tiles = region.tiles(rows)
    assert all(t.height <= rows and t.width == region.width and t.x0 == region.x0 for t in tiles)
    assert all((t.full_width, t.full_height) == (region.full_width, region.full_height) for t in tiles)
    i = np.concatenate([t.pixel_coords()[0] for t in tiles])
    j = np.concatenate([t.pixel_coords()[1] for t in tiles])
    ri, rj = region.pixel_coords()
    # same pixels in the same (row-major) order: concatenating tiles rebuilds the region
    np.testing.assert_array_equal(i, ri)
    np.testing.assert_array_equal(j, rj)
    assert sum(t.pixel_count for t in tiles) == region.pixel_count


def test_region_pixel_coords_are_absolute_row_major():
    i, j = Region(10, 8, 2, 3, 4, 2).pixel_coords()
    np.testing.assert_array_equal(i, [2, 3, 4, 5, 2, 3, 4, 5])
    np.testing.assert_array_equal(j, [3, 3, 3, 3, 4, 4, 4, 4])
    assert Region(10, 8, 2, 3).shape == (5, 8)


@pytest.mark.parametrize("args", [(0, 5), (5, 0), (10, 8, 8, 0, 3, 1), (10, 8, 0, 7, 1, 2), (10, 8, -1, 0, 2, 2)])
def test_region_outside_the_image_is_refused(args):
    with pytest.raises(ValueError):
        Region(*args)
