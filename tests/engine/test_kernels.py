"""The compiled kernels against plain numpy references written from shared/MISSION.md and their docstrings.

``cast_rays``: per-pixel displacement fields (built-in mappings fused, or given), noise, non-finite
handling, image-plane points and rays.  ``shade``: barycentric corner colors and normals, bilinear
textures that tile in both directions, the equirectangular environment (x wraps, y clamps), one
directional light plus ambient, two-sided, and the per-pixel means of color, depth, normal, direction.
"""

import numpy as np
import pytest

from rcp_server.camera.camera import Camera, Region, pixel_frames, sample_targets
from rcp_server.engine import kernels
from rcp_server.engine.kernels.embree import Hits
from rcp_server.engine.paintstate import CHANNELS, channel_shape
from rcp_server.painting.assign import displacements, setup_tile
from rcp_server.painting.loop import PaintState
from rcp_server.painting.outlines import NO_INK
from rcp_server.settings.params import PaintParams

KINDS = {
    "zero": kernels.FIELD_ZERO,
    "color": kernels.FIELD_COLOR,
    "depth": kernels.FIELD_DEPTH,
    "normal": kernels.FIELD_NORMAL,
    "given": kernels.FIELD_GIVEN,
}


# ---- cast_rays ----


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


# ---- shade ----


def ref_bilinear(texels, offset, width, height, x, y, wrap_y):
    """Bilinear lookup at texel coordinates (x, y) (texel centres at +0.5): x wraps; y wraps or clamps."""
    x = x - 0.5
    y = y - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    c0 = np.mod(x0, width).astype(np.int64)
    c1 = np.mod(x0 + 1, width).astype(np.int64)
    if wrap_y:
        r0 = np.mod(y0, height).astype(np.int64)
        r1 = np.mod(y0 + 1, height).astype(np.int64)
    else:
        r0 = np.clip(y0, 0, height - 1).astype(np.int64)
        r1 = np.clip(y0 + 1, 0, height - 1).astype(np.int64)

    def texel(r, c):
        return texels[offset + r * width + c].astype(np.float64)

    return (
        (1 - fx) * (1 - fy) * texel(r0, c0)
        + fx * (1 - fy) * texel(r0, c1)
        + (1 - fx) * fy * texel(r1, c0)
        + fx * fy * texel(r1, c1)
    )


def ref_srgb_decode(values):
    x = values.astype(np.float64) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def ref_srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def ref_texel_color(texels, offset, width, height, u, v):
    """An 8-bit RGB texture's color at (u, v): bilinear in linear light, encoded back to display values."""
    linear = ref_srgb_decode(texels)
    return ref_srgb_encode(ref_bilinear(linear, offset, width, height, u * width, (1 - v) * height, True))


def ref_shade(
    origins,
    directions,
    face,
    t,
    b1,
    b2,
    spp,
    normals,
    colors,
    uv,
    texture_id,
    texels,
    texture_offset,
    texture_width,
    texture_height,
    face_material,
    material_emission,
    material_emission_texture,
    material_unlit,
    material_alpha_cutoff,
    alpha_texels,
    texture_alpha_offset,
    environment,
    light_dir,
    ambient,
    lit,
    eye,
    camera,
    z_max,
    triangles,
    face_object,
    material_bands,
    material_outline,
):
    """Every channel of ``paintstate.CHANNELS``, in its order, as the shade kernel records them."""
    o = origins.astype(np.float64)
    d = directions.astype(np.float64)
    n = len(face)
    hit = face >= 0
    finite = np.isfinite(d).all(axis=1)
    rgb = np.zeros((n, 3))
    nrm = np.zeros((n, 3))
    z = np.full(n, float(z_max))
    # ---- hits ----
    f = face[hit]
    w = np.stack([1.0 - b1.astype(np.float64) - b2, b1.astype(np.float64), b2.astype(np.float64)], axis=1)[hit]
    albedo = np.einsum("nc,nck->nk", w, colors[f].astype(np.float64))
    nr = np.einsum("nc,nck->nk", w, normals[f].astype(np.float64))
    length = np.linalg.norm(nr, axis=1, keepdims=True)
    nr = np.where(length > 0, nr / np.where(length > 0, length, 1.0), nr)
    tid = texture_id[f]
    textured = tid >= 0
    uvs = np.einsum("nc,nck->nk", w, uv[f].astype(np.float64))
    if textured.any():
        k = tid[textured]
        tw, th = texture_width[k], texture_height[k]
        albedo[textured] *= ref_texel_color(texels, texture_offset[k], tw, th, uvs[textured, 0], uvs[textured, 1])
    dh = d[hit]
    mat = face_material[f]
    unlit = np.zeros((n, 3))
    unlit[hit] = albedo
    if lit:
        facing = np.where((nr * dh).sum(axis=1) > 0, -1.0, 1.0)
        lambert = np.maximum(-facing * (nr @ np.asarray(light_dir, np.float64)), 0.0)
        bands = material_bands[mat]
        toon = (bands > 0) & (lambert > 0)
        lambert[toon] = np.minimum(np.floor(lambert[toon] * bands[toon]) + 1, bands[toon]) / bands[toon]
        k = ambient + (1 - ambient) * lambert
        albedo *= np.where(material_unlit[mat], 1.0, k)[:, None]
    emission = material_emission[mat].astype(np.float64)
    etid = material_emission_texture[mat]
    glows = etid >= 0
    if glows.any():
        k = etid[glows]
        tw, th = texture_width[k], texture_height[k]
        emission[glows] *= ref_texel_color(texels, texture_offset[k], tw, th, uvs[glows, 0], uvs[glows, 1])
    rgb[hit] = albedo + emission
    nrm[hit] = nr
    # depth along each pixel's f_ij from its eye_ij (camera.py), the image one row of len(face) / spp pixels
    pixels = np.arange(n) // spp
    eyes, _, _, f_ij = pixel_frames(camera, Region(n // spp, 1), pixels, np.zeros_like(pixels))
    z[hit] = ((o[hit] + t[hit].astype(np.float64)[:, None] * dh - eyes[hit]) * f_ij[hit]).sum(axis=1)
    # ---- misses ----
    sky = ~hit & finite
    env_h, env_w = environment.shape[:2]
    if env_h * env_w == 1:
        rgb[sky] = environment[0, 0]
    else:
        ds = d[sky]
        lon = np.arctan2(ds[:, 0], -ds[:, 2])
        lat = 0.5 * np.pi - np.arctan2(ds[:, 1], np.hypot(ds[:, 0], ds[:, 2]))
        rgb[sky] = ref_bilinear(
            environment.reshape(-1, 3),
            0,
            env_w,
            env_h,
            (lon / (2 * np.pi) + 0.5) * env_w,
            lat / np.pi * env_h,
            False,
        )
    rgb[~hit & ~finite] = 0.0
    all_sky = (~hit).reshape(-1, spp).all(axis=1)
    # ---- the other channels: the triangle's own normal on the shading normal's side, indices, uv, points ----
    tri = triangles[f].astype(np.float64)
    g = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    geometric = np.zeros((n, 3))
    geometric[hit] = np.where(((g * nr).sum(axis=1) < 0)[:, None], -g, g)
    uv_all = np.zeros((n, 2))
    uv_all[hit] = uvs
    position = np.where(hit[:, None], o + t.astype(np.float64)[:, None] * d, np.nan)
    front = face.reshape(-1, spp)[:, 0]
    obj = np.where(front >= 0, face_object[front], -1).astype(np.float32)
    material = np.where(front >= 0, face_material[front], -1).astype(np.float32)

    def mean(a):
        return a.reshape(-1, spp, a.shape[1]).mean(axis=1)

    # ---- per-pixel means ----
    color = np.clip(rgb, 0.0, 1.0).reshape(-1, spp, 3).mean(axis=1)
    depth = z.reshape(-1, spp).mean(axis=1)
    normal = nrm.reshape(-1, spp, 3).mean(axis=1)
    total = np.where(finite[:, None], d, 0.0).reshape(-1, spp, 3).sum(axis=1)
    length = np.linalg.norm(total, axis=1, keepdims=True)
    direction = np.where(length > 0, total / np.where(length > 0, length, 1.0), 0.0)
    albedo = np.where(all_sky[:, None], color, mean(unlit))  # a pixel all sky: the sky's colour
    return color, depth, normal, direction, mean(geometric), obj, material, albedo, mean(uv_all), mean(position)


def _shade_inputs(seed, n_pix=60, spp=3, env_shape=(6, 10)):
    rng = np.random.default_rng(seed)
    n = n_pix * spp
    n_faces = 9
    normals = rng.normal(size=(n_faces, 3, 3)).astype(np.float32)
    normals[4] = 0.0  # a face without a usable normal
    colors = rng.uniform(-0.1, 1.4, (n_faces, 3, 3)).astype(np.float32)  # clamping is exercised
    uv = rng.uniform(-1.5, 2.5, (n_faces, 3, 2)).astype(np.float32)  # tiling in both directions
    texture_id = np.array([-1, 0, 1, 0, -1, 1, 0, -1, 1], np.int32)
    tex_a = rng.integers(0, 256, (3, 5, 3)).astype(np.uint8)  # h x w, 8-bit RGB
    tex_b = rng.integers(0, 256, (4, 2, 3)).astype(np.uint8)
    texels = np.concatenate([tex_a.reshape(-1, 3), tex_b.reshape(-1, 3)])
    texture_offset = np.array([0, 15], np.int64)
    texture_width = np.array([5, 2], np.int64)
    texture_height = np.array([3, 4], np.int64)
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[::3] = directions[::3] * np.array([1.0, 0.05, 1.0])  # many near the horizon
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[5:9] = (1e-3, 1.0, 2e-3)  # near the poles (at a pole itself the longitude is arbitrary)
    directions[9] = (-2e-3, -1.0, 1e-3)
    directions[10] = (0.0, 0.0, 1.0)  # straight behind: longitude +-pi, the wrap seam
    directions = directions.astype(np.float32)
    face = rng.integers(-1, n_faces, n).astype(np.int32)
    face[rng.uniform(size=n) < 0.2] = -1
    face[5:11] = -1
    nan_rays = np.zeros(n, bool)
    nan_rays[[21, 22, 23, 31]] = True  # pixel 7 casts only NaN rays, pixel 10 one of three
    directions[nan_rays] = np.nan
    face[nan_rays] = -1
    b1 = rng.uniform(0, 1, n)
    b2 = rng.uniform(0, 1, n) * (1 - b1)
    env = rng.uniform(0, 1, env_shape + (3,)).astype(np.float32)
    light = np.array([-0.3, -1.0, -0.4])
    return dict(
        origins=rng.normal(size=(n, 3)).astype(np.float32),
        directions=directions,
        face=face,
        t=rng.uniform(0.1, 10, n).astype(np.float32),
        b1=b1.astype(np.float32),
        b2=b2.astype(np.float32),
        spp=spp,
        normals=normals,
        colors=colors,
        uv=uv,
        texture_id=texture_id,
        texels=texels,
        texture_offset=texture_offset,
        texture_width=texture_width,
        texture_height=texture_height,
        alpha_texels=np.zeros(1, np.uint8),
        texture_alpha_offset=np.full(2, -1, np.int64),
        # materials: 0 plain, 1 glowing (a color), 2 glowing through texture 1, 3 unlit
        face_material=np.array([0, 1, 2, 3, 0, 3, 2, 1, 0], np.int32),
        material_emission=np.array([[0, 0, 0], [0.2, 0.1, 0.05], [0.5, 0.9, 0.3], [0, 0, 0]], np.float32),
        material_emission_texture=np.array([-1, -1, 1, -1], np.int32),
        material_unlit=np.array([False, False, False, True]),
        material_alpha_cutoff=np.zeros(4, np.float32),
        environment=env,
        light_dir=light / np.linalg.norm(light),
        ambient=0.25,
        lit=True,
        eye=np.array([0.2, -0.1, 0.3]),
        camera=Camera((0.2, -0.1, 0.3), (0.2, 0.5, -0.5)),
        z_max=50.0,
        triangles=rng.normal(size=(n_faces, 3, 3)).astype(np.float32),
        face_object=rng.integers(0, 4, n_faces).astype(np.int32),
        material_bands=np.array([0, 3, 0, 2], np.int32),  # toon on a glowing material: both apply
        material_outline=np.zeros(4, np.float32),  # outlines: tests/engine/test_outlines.py
    )


def _run_shade(inputs, need=CHANNELS[1:]):
    """Every channel, those not in ``need`` left at -9."""
    n_pix = len(inputs["face"]) // inputs["spp"]
    out = tuple(np.full(channel_shape(name, n_pix), -9.0, np.float32) for name in CHANNELS)
    kernels.shade(
        origins=inputs["origins"],
        directions=inputs["directions"],
        hits=Hits(inputs["face"], inputs["t"], inputs["b1"], inputs["b2"]),
        spp=inputs["spp"],
        pixels=np.arange(n_pix),
        surfaces=kernels.Surfaces(**{name: inputs[name] for name in kernels.Surfaces._fields}),
        environment=inputs["environment"],
        light_dir=inputs["light_dir"],
        ambient=inputs["ambient"],
        lit=inputs["lit"],
        eye=inputs["eye"],
        plane=kernels.ImagePlane.of(inputs["camera"], Region(n_pix, 1)),
        z_max=inputs["z_max"],
        out=kernels.Channels(*out),
        need=kernels.records(need),
        ink=NO_INK,
    )
    kernels.record_surfaces(
        origins=inputs["origins"],
        directions=inputs["directions"],
        hits=Hits(inputs["face"], inputs["t"], inputs["b1"], inputs["b2"]),
        spp=inputs["spp"],
        pixels=np.arange(n_pix),
        surfaces=kernels.Surfaces(**{name: inputs[name] for name in kernels.Surfaces._fields}),
        out=kernels.Channels(*out),
        need=kernels.records(need),
    )
    return out


@pytest.mark.parametrize("lit", [True, False])
@pytest.mark.parametrize("spp", [1, 3])
@pytest.mark.parametrize("seed", [0, 1])
def test_shade_matches_numpy_reference(seed, spp, lit):
    _check_shade(seed, spp, lit, None)


@pytest.mark.parametrize("projection", ["equirect", "perspective"])
@pytest.mark.parametrize("stereo", ["mono", "side-by-side"])
def test_shade_measures_depth_along_each_pixels_own_frame_from_its_own_eye(projection, stereo):
    inputs = _shade_inputs(0, spp=3)
    _check_shade(0, 3, True, inputs["camera"].moved(projection=projection, stereo=stereo, ipd=0.4))


def _check_shade(seed, spp, lit, camera):
    inputs = _shade_inputs(seed, spp=spp)
    inputs["lit"] = lit
    if camera is not None:
        inputs["camera"] = camera
    got = _run_shade(inputs)
    color, depth, normal, direction = got[:4]
    ref = ref_shade(**inputs)
    if camera is not None:  # depth is what this one checks
        np.testing.assert_allclose(depth, ref[1], rtol=1e-6, atol=1e-5)
        return
    for name, value, expected in zip(CHANNELS[4:], got[4:], ref[4:], strict=True):
        np.testing.assert_allclose(value, expected, rtol=1e-5, atol=2e-4 if name == "albedo" else 1e-5, err_msg=name)
    # the panorama's longitude and latitude come from an atan2 good to 1e-5 rad: 1e-5 texels here; a
    # texture's display value is encoded through a 4096-step table, interpolated: within 2e-4
    np.testing.assert_allclose(color, ref[0], rtol=0, atol=2e-4)
    np.testing.assert_allclose(depth, ref[1], rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(normal, ref[2], rtol=0, atol=1e-6)
    np.testing.assert_allclose(direction, ref[3], rtol=0, atol=1e-6)
    assert np.all((color >= 0) & (color <= 1))
    if spp == 3:
        # a pixel whose rays are all NaN is black, records z_max and no direction
        np.testing.assert_array_equal(color[7], 0.0)
        assert depth[7] == 50.0
        np.testing.assert_array_equal(direction[7], 0.0)


def test_shade_textured_faces_really_are_textured_and_the_sky_really_is_sampled():
    """Guard the reference test against vacuity: the inputs exercise textures, clamping and the panorama."""
    inputs = _shade_inputs(0, spp=1)
    plain = dict(inputs, texture_id=np.full_like(inputs["texture_id"], -1))
    assert not np.allclose(_run_shade(inputs)[0], _run_shade(plain)[0], atol=1e-3)
    dark = dict(inputs, material_emission=np.zeros_like(inputs["material_emission"]))
    assert not np.allclose(_run_shade(inputs)[0], _run_shade(dark)[0], atol=1e-3)
    lit_everywhere = dict(inputs, material_unlit=np.zeros_like(inputs["material_unlit"]))
    assert not np.allclose(_run_shade(inputs)[0], _run_shade(lit_everywhere)[0], atol=1e-3)
    flat_sky = dict(
        inputs, environment=np.ascontiguousarray(np.broadcast_to(inputs["environment"][:1, :1], (6, 10, 3)))
    )
    assert not np.allclose(_run_shade(inputs)[0], _run_shade(flat_sky)[0], atol=1e-3)


def test_shade_constant_environment_and_channels_not_needed_are_not_written():
    inputs = _shade_inputs(2, spp=2, env_shape=(1, 1))
    got = _run_shade(inputs, need=())
    ref = ref_shade(**inputs)
    color = got[0]
    np.testing.assert_allclose(color, ref[0], rtol=0, atol=2e-4)
    assert all(np.all(channel == -9.0) for channel in got[1:])
    sky_only = (inputs["face"].reshape(-1, 2) < 0).all(axis=1) & np.isfinite(inputs["directions"]).all(axis=1).reshape(
        -1, 2
    ).all(axis=1)
    assert sky_only.sum() > 3
    np.testing.assert_array_equal(color[sky_only], np.broadcast_to(inputs["environment"][0, 0], (sky_only.sum(), 3)))


def test_bilinear_texture_tiles_in_both_directions():
    """A texture looked up at uv and at uv + (1, 1), (-2, 3) gives the same color."""
    inputs = _shade_inputs(3, spp=1)
    inputs["face"][:] = 1  # textured face, texture 0
    inputs["directions"] = np.nan_to_num(inputs["directions"], nan=0.6)
    inputs["lit"] = False
    inputs["colors"][1] = 1.0
    base = _run_shade(inputs)[0]
    for shift in ((1.0, 1.0), (-2.0, 3.0), (0.0, -1.0)):
        moved = dict(inputs, uv=(inputs["uv"] + np.float32(shift)).astype(np.float32))
        np.testing.assert_allclose(_run_shade(moved)[0], base, rtol=0, atol=2e-6)


def test_environment_texel_centres_are_exact():
    """Looking at a texel centre of the panorama gives that texel (no blur, the documented orientation)."""
    rng = np.random.default_rng(4)
    env = rng.uniform(0, 1, (8, 16, 3)).astype(np.float32)
    row, col = np.meshgrid(np.arange(1, 7), np.arange(16), indexing="ij")
    lon = ((col + 0.5) / 16 - 0.5) * 2 * np.pi
    lat = (row + 0.5) / 8 * np.pi
    d = np.stack([np.sin(lat) * np.sin(lon), np.cos(lat), -np.sin(lat) * np.cos(lon)], axis=-1).reshape(-1, 3)
    inputs = _shade_inputs(0, n_pix=len(d), spp=1, env_shape=(8, 16))
    inputs.update(environment=env, directions=d.astype(np.float32), face=np.full(len(d), -1, np.int32))
    color = _run_shade(inputs)[0]
    # the fast atan2 is good to 1e-5 rad, 3e-5 texels here
    np.testing.assert_allclose(color, env[row.ravel(), col.ravel()], rtol=0, atol=5e-5)


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
