"""The image-space method's lookup (``engine/kernels/lookup.py``) against its numpy form in ``imagespace.py``:
every edge rule and set of channels on a perspective camera, and a camera of every projection."""

import numpy as np
import pytest
from helpers.cameras import CAMERAS, painting_size

from rcp_server.camera.camera import Camera, Region, eye_pixels
from rcp_server.engine import kernels
from rcp_server.engine.paintstate import PaintState
from rcp_server.painting.imagespace import bilinear, lookup_coords
from rcp_server.settings.params import EDGES


def _dummy(ndim):
    return np.zeros(1, np.float32) if ndim == 1 else np.zeros((1, 3), np.float32)


@pytest.mark.parametrize("channels", [("color",), ("color", "depth"), ("color", "normal", "direction")])
@pytest.mark.parametrize("edge", EDGES)
def test_look_up_kernel_matches_numpy_reference(edge, channels):
    rng = np.random.default_rng(5)
    camera = Camera((0.5, 1.0, 2.0), (-1.0, 0.0, -3.0), (0.1, 1.0, 0.0), fov=55.0)
    w, h = 23, 13
    region = Region(w, h, 3, 4, 15, 6)
    n = region.pixel_count
    p = camera.pixel_pitch(h)
    plain = {
        "color": rng.uniform(0, 1, (w * h, 3)).astype(np.float32),
        "depth": rng.uniform(1, 9, w * h).astype(np.float32),
        "normal": rng.normal(size=(w * h, 3)).astype(np.float32),
        "direction": rng.normal(size=(w * h, 3)).astype(np.float32),
    }
    plain["direction"] /= np.linalg.norm(plain["direction"], axis=1, keepdims=True)
    v_p = rng.normal(0, 12 * p, (n, 3)) @ np.diag([1.0, 1.0, 0.02])  # lookups up to a dozen pixels off screen
    v_p[0] = -2.0 * np.stack(camera.basis())[2]  # behind the eye
    v_p[1] = (np.nan, 0.0, 0.0)
    out = {name: np.full((n, 3) if name != "depth" else n, 7.0, np.float32) for name in plain}
    plane = kernels.ImagePlane.of(camera, region)
    kernels.look_up(
        v_p=v_p,
        moves=True,
        plane=plane,
        edge=EDGES.index(edge),
        plain=kernels.Channels(
            **{name: plain[name] if name in channels else _dummy(2 - (name == "depth")) for name in plain}
        ),
        out=kernels.Channels(**out),
    )
    x, y, ok = lookup_coords(v_p, camera, region)
    assert not ok[0] and not ok[1] and ok[2:].all()
    assert (x < 0).any() and (x > w - 1).any()  # the edges are exercised
    for name in plain:
        if name not in channels:
            assert np.all(out[name] == 7.0)  # not recorded, not written
            continue
        image = plain[name].reshape(h, w, *plain[name].shape[1:])
        expected = bilinear(image, x, y, edge)
        if name == "direction":
            expected /= np.linalg.norm(expected, axis=1, keepdims=True)
        np.testing.assert_allclose(out[name], expected, rtol=1e-5, atol=1e-5)
    # no displacement: each pixel reads exactly its own plain value
    kernels.look_up(
        v_p=v_p,
        moves=False,
        plane=plane,
        edge=EDGES.index(edge),
        plain=kernels.Channels(plain["color"], _dummy(1), _dummy(2), _dummy(2)),
        out=kernels.Channels(out["color"], _dummy(1), _dummy(2), _dummy(2)),
    )
    i, j = region.pixel_coords()
    np.testing.assert_array_equal(out["color"], plain["color"][j * w + i])


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_the_image_lookup_kernel_is_its_numpy_twin_on_every_projection(name):
    camera = CAMERAS[name]
    width, height = painting_size(camera)
    region = Region(width, height)
    rng = np.random.default_rng(11)
    n = region.pixel_count
    plain = PaintState(region, rng.uniform(0, 1, (n, 3)).astype(np.float32))
    v_p = rng.normal(scale=8 * camera.pixel_pitch(camera.eye_size(width, height)[1]), size=(n, 3))
    v_p[::7] *= 30.0  # far off: across the seam, past a pole, off an image plane
    out = PaintState.empty(region, frozenset({"color"}))
    kernels.look_up(
        v_p=v_p,
        moves=True,
        plane=kernels.ImagePlane.of(camera, region),
        edge=EDGES.index("mirror"),
        plain=kernels.channels(plain),
        out=kernels.channels(out),
    )
    x, y, _ = lookup_coords(v_p, camera, region)
    side, _, _ = eye_pixels(camera, region, *region.pixel_coords())
    eye_w, eye_h = camera.eye_size(width, height)
    image = plain.color.reshape(height, width, 3)
    expected = np.empty((n, 3))
    for s in camera.sides:
        mine = side == s
        x_off = eye_w if s > 0 and camera.stereo == "side-by-side" else 0
        y_off = eye_h if s > 0 and camera.stereo == "top-bottom" else 0
        own = image[y_off : y_off + eye_h, x_off : x_off + eye_w]
        edge = "sphere" if camera.projection == "equirect" else "mirror"
        expected[mine] = bilinear(own, x[mine], y[mine], edge)
    np.testing.assert_allclose(out.color, expected, atol=2e-6)
