"""``cast_rays`` (``engine/kernels/cast.py``) against a plain numpy reference written from shared/MISSION.md and its
docstring: per-pixel displacement fields (built-in mappings fused, or given), noise, non-finite handling,
image-plane points and rays, on every projection."""

import numpy as np
import pytest

from rcp_server.camera.camera import Camera, Region, pixel_frames, sample_targets
from rcp_server.engine import kernels
from rcp_server.painting.assign import displacements, setup_tile
from rcp_server.painting.loop import PaintState
from rcp_server.settings.params import PaintParams

KINDS = {
    "zero": kernels.FIELD_ZERO,
    "color": kernels.FIELD_COLOR,
    "depth": kernels.FIELD_DEPTH,
    "normal": kernels.FIELD_NORMAL,
    "given": kernels.FIELD_GIVEN,
}


def ref_field(kind, scale, frames, color, depth, normal, direction, z0, given, noise, noise_scale):
    """scale * (D + noise_scale * noise), non-finite -> 0; (n, 3) float64. frames: each pixel's r, u, f (n, 3)."""
    n = len(color)
    c = color.astype(np.float64)
    r, u, f = frames
    if kind == kernels.FIELD_ZERO:
        return np.zeros((n, 3))
    if kind == kernels.FIELD_COLOR:
        d = (2.0 * c[:, :1] - 1.0) * r + (2.0 * c[:, 1:2] - 1.0) * u + (2.0 * c[:, 2:] - 1.0) * f
    elif kind == kernels.FIELD_DEPTH:
        d = (2.0 * c[:, :1] - 1.0) * r + (2.0 * c[:, 1:2] - 1.0) * u + (2.0 * c[:, 2:] - 1.0) * f
        d = d * np.abs(depth.astype(np.float64) - z0)[:, None]
    elif kind == kernels.FIELD_NORMAL:
        d = np.cross(direction, normal).astype(np.float64)  # float32 data, float32 products (as mappings.py)
    else:
        d = given.astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        v = scale * (d + noise_scale * noise.astype(np.float64))
    return np.where(np.isfinite(v), v, 0.0)


def ref_cast_rays(camera, region, xi, eta, v_p, v_e):
    """origins (n*spp, 3) = eye_ij + V_e; unit directions towards P_p(s, t) + V_p; NaN where there is no ray."""
    i, j = region.pixel_coords()
    spp = xi.shape[1]
    target = sample_targets(camera, region, i, j, xi, eta) + np.repeat(v_p, spp, axis=0)
    eyes, *_ = pixel_frames(camera, region, i, j)
    origins = np.repeat(eyes + v_e, spp, axis=0)
    d = target - origins
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        norm = np.sqrt((d * d).sum(axis=1))
        good = (norm > 0) & np.isfinite(norm)
        directions = np.where(good[:, None], d / norm[:, None], np.nan)
    return origins, directions, int((~good).sum())


def _cast_inputs(seed, region, spp):
    rng = np.random.default_rng(seed)
    n = region.pixel_count
    unit = rng.normal(size=(n, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    data = {
        "color": rng.uniform(0, 1, (n, 3)).astype(np.float32),
        "depth": rng.uniform(0.5, 20, n).astype(np.float32),
        "normal": rng.normal(size=(n, 3)).astype(np.float32),
        "direction": unit.astype(np.float32),
        "given": rng.normal(size=(n, 3)).astype(np.float32),
        "noise": rng.uniform(-1, 1, (n, 3)).astype(np.float32),
    }
    # non-finite previous data in a few pixels: a displacement that is not finite moves nothing
    data["color"][3] = np.nan
    data["depth"][5] = np.inf
    data["normal"][7, 1] = np.nan
    data["given"][9] = (np.inf, 0.0, 1.0)
    xi = rng.uniform(0, 1, (n, spp))
    eta = rng.uniform(0, 1, (n, spp))
    return data, xi, eta


def _cast_args(camera, region, xi, eta, data, z0, target, eye, noise_scale) -> dict:
    """Every argument of kernels.cast_rays but write_origins; the outputs start at 7.0 (never written: still 7.0)."""
    n, spp = xi.shape
    return dict(
        eye=np.asarray(camera.eye, np.float64),
        plane=kernels.ImagePlane.of(camera, region),
        xi=xi,
        eta=eta,
        previous=kernels.Channels(data["color"], data["depth"], data["normal"], data["direction"]),
        z0=float(z0),
        target=kernels.Field(target[0], target[1], data["given"]),
        eye_field=kernels.Field(eye[0], eye[1], data["given"][::-1].copy()),
        noise=data["noise"],
        noise_scale=noise_scale,
        pixels=np.arange(n),
        v_p=np.full((n, 3), 7.0),
        v_e=np.full((n, 3), 7.0),
        origins=np.full((n * spp, 3), 7.0, np.float32),
        directions=np.full((n * spp, 3), 7.0, np.float32),
    )


def _run_cast(camera, region, xi, eta, data, z0, target, eye, noise_scale):
    args = _cast_args(camera, region, xi, eta, data, z0, target, eye, noise_scale)
    bad = kernels.cast_rays(**args, write_origins=True)
    return bad, args["v_p"], args["v_e"], args["origins"], args["directions"]


CAST_CAMERA = Camera((0.5, 1.0, 2.0), (-1.0, 0.0, -3.0), (0.1, 1.0, 0.0), fov=55.0)
PROJECTED = {  # a camera of every projection, and a region of its painting across both eyes where there are two
    "perspective": (CAST_CAMERA, Region(13, 9, 3, 2, 6, 4)),
    "equirect": (CAST_CAMERA.moved(projection="equirect"), Region(18, 9, 3, 2, 12, 6)),
    "perspective top-bottom": (CAST_CAMERA.moved(stereo="top-bottom", ipd=0.3), Region(13, 18, 3, 6, 6, 7)),
    "equirect side-by-side": (
        CAST_CAMERA.moved(projection="equirect", stereo="side-by-side", ipd=0.3),
        Region(36, 9, 12, 2, 12, 6),
    ),
}


@pytest.mark.parametrize("projected", sorted(PROJECTED))
@pytest.mark.parametrize("spp", [1, 3])
def test_cast_rays_matches_numpy_reference_on_every_projection(projected, spp):
    camera, region = PROJECTED[projected]
    for target_kind, eye_kind, noise_scale in (
        ("color", "depth", 0.35),
        ("given", "normal", 0.0),
        ("zero", "zero", 0.0),
    ):
        _check_cast(camera, region, spp, target_kind, eye_kind, noise_scale)


@pytest.mark.parametrize("noise_scale", [0.0, 0.35])
@pytest.mark.parametrize("eye_kind", sorted(KINDS))
@pytest.mark.parametrize("target_kind", sorted(KINDS))
def test_cast_rays_matches_numpy_reference(target_kind, eye_kind, noise_scale):
    _check_cast(CAST_CAMERA, Region(13, 9, 3, 2, 6, 4), 3, target_kind, eye_kind, noise_scale)


def _check_cast(camera, region, spp, target_kind, eye_kind, noise_scale):
    data, xi, eta = _cast_inputs(1, region, spp)
    z0 = 4.5
    target = (KINDS[target_kind], 0.07)
    eye = (KINDS[eye_kind], 0.3)
    if spp == 1:
        xi = eta = np.full((region.pixel_count, 1), 0.5)
    bad, v_p, v_e, origins, directions = _run_cast(camera, region, xi, eta, data, z0, target, eye, noise_scale)
    frames = pixel_frames(camera, region, *region.pixel_coords())[1:]
    ref_vp = ref_field(
        target[0],
        target[1],
        frames,
        data["color"],
        data["depth"],
        data["normal"],
        data["direction"],
        z0,
        data["given"],
        data["noise"],
        noise_scale,
    )
    ref_ve = ref_field(
        eye[0],
        eye[1],
        frames,
        data["color"],
        data["depth"],
        data["normal"],
        data["direction"],
        z0,
        data["given"][::-1],
        data["noise"],
        noise_scale,
    )
    # a field that does not move is neither written nor read (the buffers keep their 7.0)
    np.testing.assert_allclose(v_p, ref_vp if target_kind != "zero" else 7.0, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(v_e, ref_ve if eye_kind != "zero" else 7.0, rtol=1e-12, atol=1e-14)
    ref_o, ref_d, ref_bad = ref_cast_rays(camera, region, xi, eta, ref_vp, ref_ve)
    assert bad == ref_bad == 0
    np.testing.assert_allclose(origins, ref_o.astype(np.float32), rtol=0, atol=1e-6)
    np.testing.assert_allclose(directions, ref_d, rtol=0, atol=2e-7)
    if target_kind != "zero" or eye_kind != "zero":
        plain = ref_cast_rays(camera, region, xi, eta, np.zeros_like(ref_vp), np.zeros_like(ref_ve))[1]
        assert not np.allclose(directions, plain, atol=1e-4)  # the fields did move something


@pytest.mark.parametrize("target_kind", ["zero", "color", "depth"])
@pytest.mark.parametrize("region", [Region(13, 9, 3, 2, 6, 4), Region(7, 5), Region(31, 17, 0, 9, 31, 8)])
def test_cast_rays_one_pass_for_an_eye_at_rest_is_bit_for_bit_the_general_one(target_kind, region):
    """One sample a pixel, one flat eye at rest, no noise: ``cast_rays`` takes its one-pass path when it casts
    every pixel of the tile, and its general one for any other list. Both give the same bits and count the
    same bad rays (non-finite colours and depths move nothing; a field of 1e300 overflows)."""
    data, _, _ = _cast_inputs(4, region, 1)
    centre = np.full((region.pixel_count, 1), 0.5)
    data["color"][0] = (np.inf, 0.5, 0.5)
    data["depth"][4] = np.nan
    for scale in (0.07, 1e300):
        args = _cast_args(CAST_CAMERA, region, centre, centre, data, 4.5, (KINDS[target_kind], scale), ("zero", 0.0), 0)
        args["eye_field"] = args["eye_field"]._replace(kind=kernels.FIELD_ZERO)
        for write_origins in (True, False):
            one_pass = dict(
                args, v_p=args["v_p"].copy(), origins=args["origins"].copy(), directions=args["directions"].copy()
            )
            general = dict(
                args, v_p=args["v_p"].copy(), origins=args["origins"].copy(), directions=args["directions"].copy()
            )
            general["pixels"] = np.arange(1, region.pixel_count)  # not every pixel: the general path
            bad = kernels.cast_rays(**one_pass, write_origins=write_origins)
            bad_general = kernels.cast_rays(**general, write_origins=write_origins)
            np.testing.assert_array_equal(one_pass["directions"][1:], general["directions"][:-1])
            np.testing.assert_array_equal(one_pass["origins"][1:], general["origins"][:-1])
            assert bad == bad_general + bool(np.isnan(one_pass["directions"][0]).any())
            assert bad == int(np.isnan(one_pass["directions"]).any(axis=1).sum())
            overflows = scale > 1 and target_kind != "zero"  # every pixel but the few whose field is not finite
            assert (bad > region.pixel_count - 5) if overflows else bad == 0
            assert np.all(one_pass["origins"] == 7.0) != write_origins
            assert np.all(one_pass["v_p"] == 7.0)  # the one pass took it: it keeps the field in registers
    frames = pixel_frames(CAST_CAMERA, region, *region.pixel_coords())[1:]
    field = (data["color"], data["depth"], data["normal"], data["direction"], 4.5, data["given"], data["noise"], 0.0)
    ref_vp = ref_field(KINDS[target_kind], 0.07, frames, *field)
    _, ref_d, _ = ref_cast_rays(CAST_CAMERA, region, centre, centre, ref_vp, np.zeros_like(ref_vp))
    args = _cast_args(CAST_CAMERA, region, centre, centre, data, 4.5, (KINDS[target_kind], 0.07), ("zero", 0.0), 0)
    kernels.cast_rays(**dict(args, eye_field=args["eye_field"]._replace(kind=kernels.FIELD_ZERO)), write_origins=True)
    np.testing.assert_allclose(args["directions"], ref_d, rtol=0, atol=2e-7)


def test_cast_rays_counts_rays_that_overflow_and_leaves_them_nan():
    camera = Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0))
    region = Region(8, 6)
    data, xi, eta = _cast_inputs(2, region, 2)
    data["given"][:] = 0.0
    data["given"][[4, 10]] = (1.0, 0.0, 0.0)
    bad, v_p, _, origins, directions = _run_cast(
        camera, region, xi, eta, data, 1.0, (kernels.FIELD_GIVEN, 1e300), (kernels.FIELD_ZERO, 0.0), 0.0
    )
    # |P_p + 1e300 r - eye|^2 overflows: no ray for those pixels' samples, and they are counted
    assert bad == 4
    nan_rows = np.isnan(directions).any(axis=1)
    np.testing.assert_array_equal(np.flatnonzero(nan_rows), [8, 9, 20, 21])
    assert np.all(np.isnan(directions[nan_rows]))
    assert np.all(np.isfinite(origins))
    np.testing.assert_allclose(np.linalg.norm(directions[~nan_rows], axis=1), 1.0, atol=1e-6)


def test_cast_rays_agrees_with_the_painting_reference():
    """raytrace.displacements is the numpy form of the fused fields; TileSetup.plane of the image plane."""
    camera = Camera((1.0, 0.5, 4.0), (0.0, 0.0, 0.0), fov=45.0)
    region = Region(20, 14, 4, 3, 9, 7)
    for mapping in ("color", "depth", "normal"):
        params = PaintParams(mapping=mapping, eye_mapping="depth", lambda_p=6.0, lambda_e=0.2, noise=0.4, spp=2)
        setup = setup_tile(camera, region, params)
        data, _, _ = _cast_inputs(3, region, 2)
        state = PaintState(region, data["color"], data["depth"], data["normal"].copy(), data["direction"])
        v_p, v_e = displacements(state, setup, params, 3.0)
        pitch = setup.pitch()
        data["noise"] = setup.noise
        _, kv_p, kv_e, origins, directions = _run_cast(
            camera,
            region,
            setup.xi,
            setup.eta,
            data,
            3.0,
            (KINDS[mapping], params.lambda_p * pitch),
            (kernels.FIELD_DEPTH, params.lambda_e),
            params.noise,
        )
        # the mappings' numpy fields are float32 (the state's dtype); the kernel sums in float64
        np.testing.assert_allclose(kv_p, v_p, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(kv_e, v_e, rtol=1e-6, atol=1e-7)
        target = setup.targets() + np.repeat(v_p, 2, axis=0) - (np.asarray(camera.eye) + np.repeat(v_e, 2, axis=0))
        np.testing.assert_allclose(directions, target / np.linalg.norm(target, axis=1, keepdims=True), atol=2e-7)


def test_cast_rays_leaves_origins_alone_when_told_they_already_hold_the_eye():
    camera = Camera((0.5, 1.0, 2.0), (-1.0, 0.0, -3.0))
    region = Region(6, 4)
    data, xi, eta = _cast_inputs(4, region, 1)
    args = _cast_args(camera, region, xi, eta, data, 1.0, (kernels.FIELD_COLOR, 0.1), (kernels.FIELD_ZERO, 0.0), 0.0)
    origins = args["origins"]
    kernels.cast_rays(**args, write_origins=False)
    assert np.all(origins == 7.0)  # untouched
    kernels.cast_rays(**args, write_origins=True)
    np.testing.assert_array_equal(origins, np.broadcast_to(np.float32(camera.eye), origins.shape))
