"""``shade`` (``engine/kernels/shade.py``) against a plain numpy reference written from shared/MISSION.md and its
docstring: barycentric corner colors and normals, bilinear textures that tile in both directions, the
equirectangular environment (x wraps, y clamps), one directional light plus ambient, two-sided, and the
per-pixel means of color, depth, normal, direction."""

import numpy as np
import pytest

from rcp_server.camera.camera import Camera, Region, pixel_frames
from rcp_server.engine import kernels
from rcp_server.engine.kernels.embree import Hits
from rcp_server.engine.paintstate import CHANNELS, channel_shape
from rcp_server.painting.outlines import NO_INK

MATERIALS = kernels.Materials._fields[:-1]  # the tables, beside the ink


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


def _run_shade(inputs, need=CHANNELS[1:], plain=False):
    """Every channel, those not in ``need`` left at -9. ``plain``: shade is told every face is plain (no
    materials), as a painting of such a scene tells it."""
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
        out=kernels.Channels(*out),
        materials=None if plain else kernels.Materials(**{name: inputs[name] for name in MATERIALS}, ink=NO_INK),
    )
    kernels.record_surfaces(
        origins=inputs["origins"],
        directions=inputs["directions"],
        hits=Hits(inputs["face"], inputs["t"], inputs["b1"], inputs["b2"]),
        spp=inputs["spp"],
        pixels=np.arange(n_pix),
        surfaces=kernels.Surfaces(**{name: inputs[name] for name in kernels.Surfaces._fields}),
        eye=inputs["eye"],
        plane=kernels.ImagePlane.of(inputs["camera"], Region(n_pix, 1)),
        z_max=inputs["z_max"],
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


@pytest.mark.parametrize("lit", [True, False])
def test_a_painting_of_plain_faces_shades_the_same_told_there_are_no_materials(lit):
    """Where every face is plain, shade without the materials (their passes not even compiled) gives the same
    bits as shade with them, every channel."""
    inputs = _shade_inputs(5, spp=2)
    inputs.update(face_material=np.zeros_like(inputs["face_material"]), lit=lit)
    for told, untold in zip(_run_shade(inputs), _run_shade(inputs, plain=True), strict=True):
        np.testing.assert_array_equal(told, untold)
    assert len(kernels.shade.signatures) >= 2  # two compilations: one with the materials' passes, one without


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
