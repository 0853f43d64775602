"""Every projection (``camera.py``, "Other projections"): the local frame and the sizes each takes, the
equirect panorama's conventions on scenes whose answer is known, and the method's guarantees on each: the plain
render at lambda 0, a tile equal to its crop, each eye of a stereo painting as that eye's
own painting, and the image-space lookup through the inverse map. The compiled functions against their numpy
twins are in ``tests/engine/test_projection.py`` and ``test_lookup.py``.
"""

import numpy as np
import pytest
from helpers.cameras import CAMERAS, EYE, EYE_SIZE, painting_size
from helpers.scenes import facing_plane, make_scene, noise_texture, sphere, translate, wavy_sky

from rcp_server.bench.projection import rivalry
from rcp_server.camera.camera import Camera, CameraError, Region, pixel_frames
from rcp_server.engine import kernels
from rcp_server.painting.imagespace import bilinear
from rcp_server.painting.loop import paint
from rcp_server.painting.seen import visible_faces
from rcp_server.painting.stereo import partners
from rcp_server.scene.meshes import primitive
from rcp_server.scene.scene import Environment, Light, SceneObject
from rcp_server.settings.params import PaintParams

# ---- the local frame and the sizes ----


def test_the_local_frame_is_orthonormal_and_right_handed_all_around():
    camera = CAMERAS["equirect"]
    region = Region(*painting_size(camera))
    _, r, u, f = pixel_frames(camera, region, *region.pixel_coords())
    for a, b in ((r, u), (u, f), (f, r)):
        np.testing.assert_allclose((a * b).sum(axis=1), 0.0, atol=1e-12)
    for v in (r, u, f):
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(r, f), u, atol=1e-12)  # u = r x f, as the camera's own basis
    # the centre of the panorama looks along the camera's f, with its r and u
    w, h = region.full_width, region.full_height
    centre = (h // 2) * w + w // 2
    assert np.dot(f[centre], camera.basis()[2]) > 0.99


def test_sizes_a_projection_cannot_take_are_refused_in_one_line():
    with pytest.raises(CameraError, match="width must be 2 x height"):
        CAMERAS["equirect"].image_size(100, 40)
    assert CAMERAS["equirect top-bottom"].image_size(96, 48) == (96, 96)
    assert CAMERAS["perspective side-by-side"].image_size(64, 40) == (128, 40)
    with pytest.raises(CameraError, match="two eye images"):
        paint(make_scene([]), CAMERAS["perspective side-by-side"], 63, 40, PaintParams(iterations=1))
    with pytest.raises(CameraError, match="unknown projection"):
        EYE.moved(projection="fisheye")
    with pytest.raises(CameraError, match="ipd"):
        EYE.moved(ipd=-1.0)


# ---- the panorama's conventions, on scenes whose picture is known ----


def test_an_equirect_painting_of_the_sky_is_the_panorama_itself():
    """A camera looking down -z with y up sees the environment as it is stored (shared/MISSION.md's
    equirectangular environment and camera.py's equirect): pixel for pixel at the panorama's own size."""
    rng = np.random.default_rng(5)
    u, v = np.meshgrid(np.linspace(0, 1, 96), np.linspace(0, 1, 48))
    sky = np.stack([u, v, 0.5 + 0.4 * np.sin(9 * u) * np.cos(5 * v)], axis=2).astype(np.float32)
    sky += rng.uniform(0, 0.05, sky.shape).astype(np.float32)
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), projection="equirect")
    image = paint(make_scene([], environment=Environment(sky)), camera, 96, 48, PaintParams(iterations=1)).image
    assert np.abs(image - np.clip(sky, 0, 1)).max() < 1 / 255


def test_depth_on_the_sphere_is_the_distance_from_the_eye_all_around():
    """Inside a ball of radius 5 every pixel's depth along its own f_ij is the distance to the ball."""
    ball = SceneObject("ball", *_ball(5.0))
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), projection="equirect")
    for stereo in ("mono", "side-by-side"):
        probe = PaintParams(mapping="depth", eye_mapping="test-probe", lambda_p=0.0, lambda_e=1e-9, iterations=1)
        state = paint(make_scene([ball]), camera.moved(stereo=stereo, ipd=0.2), *_painting(camera, stereo), probe)
        depth = state.state.depth
        # the ball is an icosphere: between its faces' distance and its radius (an eye 0.1 off centre: +-0.1)
        slack = 0.1 if stereo != "mono" else 0.0
        assert depth.min() > 5.0 * 0.985 - slack and depth.max() < 5.0 + slack + 1e-4


def _ball(radius: float):
    part = primitive("sphere", subdivisions=4, radius=radius).tinted((0.7, 0.6, 0.5))
    return part, [(translate(0.0, 0.0, 0.0), part)]


def _painting(camera: Camera, stereo: str) -> tuple[int, int]:
    return camera.moved(stereo=stereo).image_size(*EYE_SIZE[camera.projection])


# ---- the method on every projection ----


@pytest.fixture(scope="module")
def surround():
    """Things in every direction around EYE (ahead, behind across the panorama's seam, to the sides, above and
    below), some thinner than a pixel, a textured wall, a panorama sky, a light."""
    texture = noise_texture(7)
    objects = [
        facing_plane(9.0, size=(30.0, 8.0), divisions=(6, 2), texture=texture, center=(0.0, -3.0), uv_repeat=(4, 1)),
        sphere((-1.4, 0.4, -5.0), 1.0, 3, (0.9, 0.2, 0.1), "red"),
        sphere((2.5, 0.6, 4.0), 1.2, 2, (0.2, 0.3, 0.95), "blue behind"),
        sphere((0.1, 0.0, 6.0), 0.7, 2, (0.9, 0.9, 0.2), "on the seam"),
        sphere((-5.0, -0.5, 0.5), 1.5, 2, (0.3, 0.9, 0.4), "left"),
        sphere((0.5, 6.0, -0.5), 1.0, 2, (0.9, 0.5, 0.9), "above"),
        _pole(0.3, -5.0, 0.02),
        _pole(-0.4, 5.5, 0.03),  # behind
        _pole(4.0, 0.2, 0.04),  # to the right
        SceneObject("floor", *_floor()),
    ]
    light = Light(tuple(np.array([-0.3, -1.0, -0.4]) / np.linalg.norm([-0.3, -1.0, -0.4])), 0.3)
    return make_scene(objects, camera=EYE, light=light, environment=wavy_sky())


def _pole(x: float, z: float, radius: float) -> SceneObject:
    part = primitive("cylinder", radius=radius, height=6.0, sections=6).tinted((0.95, 0.9, 0.2))
    return SceneObject("pole", part, [(translate(x, -1.0, z), part)])


def _floor():
    part = primitive("grid", size=(24.0, 24.0), divisions=(8, 8)).tinted((0.5, 0.45, 0.4))
    return part, [(translate(0.0, -2.0, 0.0), part)]


LAMBDA = {"color": 12.0, "depth": 3.0, "normal": 14.0}


def _close_share(a: np.ndarray, b: np.ndarray) -> float:
    return float((np.abs(a - b).max(axis=-1) <= 2 / 255 + 1e-6).mean())


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_lambda_zero_paints_the_plain_render_on_every_projection(surround, name):
    camera = CAMERAS[name]
    plain = paint(surround, camera, *painting_size(camera), PaintParams(iterations=1)).image
    still = paint(surround, camera, *painting_size(camera), PaintParams(lambda_p=0.0, iterations=4)).image
    np.testing.assert_array_equal(still, plain)


@pytest.mark.parametrize("name", ["equirect", "perspective top-bottom", "equirect top-bottom"])
def test_temporal_mode_continues_each_eyes_painting(surround, name):
    """Frames that go on from the one before (each eye from its own, or with the eyes sharing), a step apart."""
    for camera in (CAMERAS[name], CAMERAS[name].moved(eyes="shared")):
        params = PaintParams(lambda_p=12.0, iterations=2)
        exact = None
        for k in range(3):
            step = camera.moved(eye=tuple(np.add(camera.eye, (0.05 * k, 0.0, -0.05 * k))))
            exact = paint(surround, step, *painting_size(step), params, previous=exact and exact.state)
        fresh = paint(surround, step, *painting_size(step), params).image
        assert np.abs(exact.image - fresh).max() > 0.1  # it did continue, not start again


@pytest.mark.parametrize("name", ["equirect", "perspective side-by-side"])
def test_the_image_method_continues_a_panorama_and_a_pair(surround, name):
    camera = CAMERAS[name]
    params = PaintParams(lambda_p=6.0, iterations=2, method="image")
    first = paint(surround, camera, *painting_size(camera), params)
    again = paint(surround, camera, *painting_size(camera), params, previous=first.state)
    plain = paint(surround, camera, *painting_size(camera), PaintParams(iterations=1)).image
    assert np.abs(again.image - first.image).max() > 0.05 and np.abs(first.image - plain).max() > 0.1
    assert np.isfinite(again.image).all() and (again.image >= 0).all() and (again.image <= 1).all()


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_a_tile_across_the_eyes_equals_its_crop(surround, name):
    camera = CAMERAS[name]
    width, height = painting_size(camera)
    for params in (PaintParams(lambda_p=12.0), PaintParams(lambda_p=12.0, spp=4, noise=0.3)):
        full = paint(surround, camera, width, height, params).state
        tile = Region(width, height, width // 3, height // 3, width // 2, height // 2)  # across both eyes
        part = paint(surround, camera, width, height, params, region=tile).state
        crop = full.color.reshape(height, width, 3)[tile.y0 : tile.y0 + tile.height, tile.x0 : tile.x0 + tile.width]
        np.testing.assert_array_equal(part.color.reshape(tile.height, tile.width, 3), crop)


@pytest.mark.parametrize("name", ["equirect", "perspective top-bottom"])
def test_bands_are_the_crops_of_the_painting(surround, name):
    """How Ray paints a panorama or a stereo pair: in bands of rows, each painted apart."""
    camera = CAMERAS[name]
    width, height = painting_size(camera)
    params = PaintParams(lambda_p=12.0)
    full = paint(surround, camera, width, height, params).image
    for band in Region(width, height).tiles(17):
        image = paint(surround, camera, width, height, params, region=band).image
        np.testing.assert_array_equal(image, full[band.y0 : band.y0 + band.height])


def test_each_eye_of_a_perspective_pair_is_the_painting_of_that_eye(surround):
    """Both eyes look along f from ``eye -/+ (ipd/2) r`` (parallel axes), each painted from its own previous image:
    each half of the pair is the mono painting of a camera standing there."""
    pair = CAMERAS["perspective side-by-side"]
    width, height = EYE_SIZE["perspective"]
    # the depth of a miss given: the scene's own is measured from the camera's (centre) eye
    params = PaintParams(mapping="depth", lambda_p=3.0, z0=5.0, z_max=40.0)
    image = paint(surround, pair, 2 * width, height, params).image
    r = pair.basis()[0]
    for side, half in ((-1, image[:, :width]), (1, image[:, width:])):
        shift = 0.5 * pair.ipd * side * r
        alone = EYE.moved(eye=tuple(np.add(EYE.eye, shift)), look_at=tuple(np.add(EYE.look_at, shift)))
        mono = paint(surround, alone, width, height, params).image
        assert _close_share(half, mono) >= 0.995
    assert np.abs(image[:, :width] - image[:, width:]).max() > 0.2  # and the two eyes differ


# ---- the image-space variant through the inverse map ----


def test_an_equirect_lookup_wraps_round_the_seam_and_over_the_poles():
    """A panorama has no edge: half a turn of longitude wraps; a step past a pole comes down the other side."""
    w, h = 8, 4
    image = np.arange(w * h, dtype=np.float64).reshape(h, w)
    # between the last column and the first: their mean
    assert bilinear(image, np.array([w - 0.5]), np.array([1.0]), "sphere")[0] == pytest.approx(
        (image[1, -1] + image[1, 0]) / 2
    )
    # half a pixel above row 0's centre is the pole: the mean of row 0 here and half a turn round
    value = bilinear(image, np.array([1.0]), np.array([-0.5]), "sphere")[0]
    assert value == pytest.approx((image[0, 1] + image[0, 1 + w // 2]) / 2)


# ---- stereo: where the eyes see the same point, and eyes that share their smudges ----


def test_the_eyes_partners_on_a_facing_plane_are_apart_by_its_disparity():
    """Parallel eyes ipd apart see a plane at depth d shifted by ipd x focal length / d pixels."""
    width, height, depth, ipd = 64, 40, 4.0, 0.4
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), fov=60.0, stereo="side-by-side", ipd=ipd)
    scene = make_scene([facing_plane(depth, size=(40.0, 40.0))], camera=camera)
    region = Region(2 * width, height)
    seen = kernels.Seen.empty(2 * width, height)
    visible_faces(scene, 0.0, camera, region, seen)
    pair = partners(camera, region, seen)
    disparity = ipd * (height / 2) / np.tan(np.radians(30.0)) / depth
    i, j = region.pixel_coords()
    left = np.flatnonzero((i < width) & (i >= 8))
    assert (pair[left] >= 0).all()
    np.testing.assert_array_equal(pair[left] // (2 * width), j[left])
    assert np.abs(pair[left] % (2 * width) - (i[left] + width - disparity)).max() <= 0.5 + 1e-9
    right = np.flatnonzero((i >= width + 8) & (pair >= 0))
    assert len(right) > 0.8 * (width - 8) * height
    np.testing.assert_array_equal(pair[pair[right]], right)  # partners both ways


@pytest.mark.parametrize("name", ["perspective side-by-side", "equirect top-bottom"])
def test_shared_eyes_smudge_the_same_point_alike(surround, name):
    """With shared eyes the left eye paints as it does alone, and the right follows it: fewer pixels where the two
    eyes' smudges of one point disagree (``rcp bench projection`` measures it on the shipped scenes)."""
    own = CAMERAS[name]
    shared = own.moved(eyes="shared")
    width, height = painting_size(own)
    params = PaintParams(lambda_p=12.0)
    alone = paint(surround, own, width, height, params).image
    both = paint(surround, shared, width, height, params).image
    left = (slice(None), slice(0, width // 2)) if own.stereo == "side-by-side" else (slice(0, height // 2),)
    np.testing.assert_array_equal(both[left], alone[left])
    if own.projection == "perspective":  # the panorama's eyes at this size and so near: no clear gain (the bench's)
        eye_size = own.eye_size(width, height)
        rivalry_own, pairs = rivalry(surround, own, *eye_size, params)
        rivalry_shared, _ = rivalry(surround, shared, *eye_size, params)
        assert pairs > 0.2 * eye_size[0] * eye_size[1] and rivalry_shared < 0.6 * rivalry_own


def test_shared_eyes_paint_the_whole_painting_by_tracing():
    camera = CAMERAS["perspective top-bottom"].moved(eyes="shared")
    with pytest.raises(ValueError, match="whole painting"):
        paint(make_scene([]), camera, 64, 80, PaintParams(), region=Region(64, 80, 0, 0, 64, 40))
    with pytest.raises(ValueError, match="traced"):
        paint(make_scene([]), camera, 64, 80, PaintParams(method="image"))
