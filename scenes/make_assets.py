"""Generate the image assets of the shipped scenes into ``scenes/assets/`` (numpy + Pillow, seeded).

    python scenes/make_assets.py

Deterministic: the same code writes the same files. The generated PNGs are committed, so a fresh clone
needs no run of this script; run it again only after changing it.

- ``sky.png``     equirectangular sky, 1024 x 512: longitude 0 (the middle column) looks along -z, +x a
                  quarter turn right; the top row is straight up. Blue gradient, a low warm sun, soft
                  clouds; below the horizon a hazy land colour.
- ``ground.png``  the village ground, 1024 x 1024, a map seen from above (+x right, top = -z): grass, a
                  sandy path along z, a square, and a patchwork of coloured fields around.
- ``sea.png``     subtle blue-green variation for the sea surface, 256 x 256, tileable.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from PIL import Image

ASSETS = Path(__file__).resolve().parent / "assets"

# the sun of sky.png; scenes light with direction = -SUN (see scenes/README.md)
SUN_LONGITUDE = 150.0  # degrees, to the right of -z (so behind the default camera, on its right)
SUN_ELEVATION = 28.0  # degrees above the horizon


# ---- tileable value noise ----


def _value_noise(rng: np.random.Generator, shape: tuple[int, int], cells: tuple[int, int]) -> np.ndarray:
    """Smooth noise in [0, 1], periodic in both axes: (h, w) float64 from a (cells_y, cells_x) lattice."""
    h, w = shape
    lattice = rng.random(cells)
    y = np.arange(h) / h * cells[0]
    x = np.arange(w) / w * cells[1]
    y0, x0 = np.floor(y).astype(int), np.floor(x).astype(int)
    fy, fx = y - y0, x - x0
    fy, fx = fy * fy * (3 - 2 * fy), fx * fx * (3 - 2 * fx)  # smoothstep: no lattice creases
    y1, x1 = (y0 + 1) % cells[0], (x0 + 1) % cells[1]
    y0, x0 = y0 % cells[0], x0 % cells[1]
    top = lattice[y0][:, x0] * (1 - fx) + lattice[y0][:, x1] * fx
    bottom = lattice[y1][:, x0] * (1 - fx) + lattice[y1][:, x1] * fx
    return top * (1 - fy[:, None]) + bottom * fy[:, None]


def fbm(
    rng: np.random.Generator, shape: tuple[int, int], cells: tuple[int, int], octaves: int, gain: float = 0.5
) -> np.ndarray:
    """Fractal sum of value noise, normalised to [0, 1]: (h, w) float64."""
    total = np.zeros(shape)
    amplitude, norm = 1.0, 0.0
    for k in range(octaves):
        total += amplitude * _value_noise(rng, shape, (cells[0] * 2**k, cells[1] * 2**k))
        norm += amplitude
        amplitude *= gain
    return total / norm


def noise_at(lattice: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Value noise of a periodic lattice (cy, cx) at continuous lattice coordinates, any shape."""
    cy, cx = lattice.shape
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    xa, xb, ya, yb = x0 % cx, (x0 + 1) % cx, y0 % cy, (y0 + 1) % cy
    top = lattice[ya, xa] * (1 - fx) + lattice[ya, xb] * fx
    bottom = lattice[yb, xa] * (1 - fx) + lattice[yb, xb] * fx
    return top * (1 - fy) + bottom * fy


def _smoothstep(a: float, b: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - a) / (b - a), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _mix(a, b, t) -> np.ndarray:
    t = np.asarray(t)[..., None]
    return np.asarray(a) * (1 - t) + np.asarray(b) * t


def _save(name: str, rgb: np.ndarray, colors: int | None = None) -> None:
    """Write (h, w, 3) float in [0, 1] as PNG; ``colors`` quantises to a palette to keep the file small."""
    image = Image.fromarray((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8), "RGB")
    if colors:
        image = image.quantize(colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    ASSETS.mkdir(exist_ok=True)
    image.save(ASSETS / name, optimize=True)
    print(f"{name}: {image.size[0]}x{image.size[1]}, {(ASSETS / name).stat().st_size // 1024} KB")


# ---- sky ----


def sky(width: int = 1024, height: int = 512) -> np.ndarray:
    rng = np.random.default_rng(7)
    lat = (np.arange(height) + 0.5) / height * math.pi  # polar angle: 0 straight up
    lon = ((np.arange(width) + 0.5) / width - 0.5) * 2 * math.pi
    lat, lon = np.meshgrid(lat, lon, indexing="ij")
    d = np.stack([np.sin(lon) * np.sin(lat), np.cos(lat), -np.cos(lon) * np.sin(lat)], axis=-1)
    elevation = 90.0 - np.degrees(lat)
    sl, se = math.radians(SUN_LONGITUDE), math.radians(SUN_ELEVATION)
    sun = np.array([math.sin(sl) * math.cos(se), math.sin(se), -math.cos(sl) * math.cos(se)])
    cos_sun = d @ sun

    # blue above, pale warm at the horizon
    up = _smoothstep(0.0, 55.0, elevation) ** 0.7
    rgb = _mix((0.93, 0.86, 0.74), (0.16, 0.38, 0.80), up)
    # sun: glow, halo and a disc
    rgb += np.array([1.0, 0.62, 0.28])[None, None] * (0.45 * np.clip(cos_sun, 0, 1) ** 12)[..., None]
    rgb += np.array([1.0, 0.85, 0.55])[None, None] * (0.6 * np.clip(cos_sun, 0, 1) ** 300)[..., None]
    rgb = np.where((cos_sun > math.cos(math.radians(2.0)))[..., None], (1.0, 1.0, 1.0), rgb)

    # soft clouds on a flat layer overhead, so they shrink in perspective towards the horizon
    height_above = np.maximum(d[..., 1], 0.02)
    px, py = d[..., 0] / height_above, d[..., 2] / height_above
    density, norm = np.zeros((height, width)), 0.0
    for octave in range(5):
        lattice, k = rng.random((64, 64)), 2.0**octave
        density += 0.55**octave * noise_at(lattice, 1.3 * k * px + 17.0, 0.7 * k * py + 29.0)
        norm += 0.55**octave
    density /= norm
    band = _smoothstep(1.5, 8.0, elevation)
    clear = 1 - 0.85 * _smoothstep(math.cos(math.radians(14)), math.cos(math.radians(5)), cos_sun)
    cover = _smoothstep(0.5, 0.7, density) * band * clear  # the sun shines through a gap
    lit = 0.5 + 0.5 * np.clip(cos_sun, 0, 1)
    cloud = _mix((0.86, 0.84, 0.90), (1.0, 0.95, 0.88), lit)
    shade = _smoothstep(0.6, 0.8, density)[..., None] * 0.14  # thicker clouds darker underneath
    rgb = _mix(rgb, cloud - shade, 0.9 * cover)

    # below the horizon: hazy distant land, darker downwards
    below = _smoothstep(0.0, -1.5, elevation)
    land = _mix((0.62, 0.70, 0.62), (0.28, 0.40, 0.24), _smoothstep(0.0, -30.0, elevation))
    rgb = _mix(rgb, land, below)
    return rgb


# ---- village ground ----

GROUND_SIZE = 100.0  # scene units the ground texture spans (default.toml's ground grid)


def ground(size: int = 1024) -> np.ndarray:
    rng = np.random.default_rng(11)
    # world coordinates of each texel: +x right, top row is -z
    c = (np.arange(size) + 0.5) / size * GROUND_SIZE - GROUND_SIZE / 2
    z, x = np.meshgrid(c, c, indexing="ij")

    lush = fbm(rng, (size, size), (8, 8), 4)
    rgb = _mix((0.24, 0.55, 0.12), (0.45, 0.72, 0.18), lush)  # grass, two greens

    # patchwork fields on a jittered lattice of 16-unit cells, away from the village
    cell = 16.0
    ci, cj = np.floor((x + 8) / cell).astype(int), np.floor((z + 8) / cell).astype(int)
    field_colors = np.array(
        [
            (0.98, 0.82, 0.08),  # rapeseed yellow
            (0.62, 0.38, 0.85),  # lavender
            (0.90, 0.20, 0.12),  # poppies
            (0.96, 0.55, 0.10),  # pumpkins
            (0.55, 0.80, 0.20),  # young wheat
            (0.80, 0.62, 0.30),  # stubble
        ]
    )
    pick = rng.integers(0, len(field_colors), (32, 32))
    stripe_dir = rng.uniform(0, math.pi, (32, 32))
    kind = pick[cj % 32, ci % 32]
    angle = stripe_dir[cj % 32, ci % 32]
    rows = 0.5 + 0.5 * np.sin((x * np.cos(angle) + z * np.sin(angle)) * 2 * math.pi / 1.6)
    color = field_colors[kind] * (0.82 + 0.18 * rows)[..., None]
    # a grass margin between fields, and no fields in the village (|x| < 20, |z| < 28)
    u, v = (x + 8) / cell - ci, (z + 8) / cell - cj
    inner = _smoothstep(0.04, 0.09, np.minimum(u, 1 - u)) * _smoothstep(0.04, 0.09, np.minimum(v, 1 - v))
    # whole cells only: a cell is a field when its centre lies outside the village
    cx, cz = ci * cell, cj * cell
    outside = ((np.abs(cx) > 20.0) | (np.abs(cz) > 20.0)) & (cx != 0)  # the path keeps a grass lane
    has_field = rng.random((32, 32))[cj % 32, ci % 32] < 0.8
    rgb = _mix(rgb, color, inner * outside * has_field)

    # flower meadow speckles in the grass
    speck = _value_noise(rng, (size, size), (160, 160))
    flowers = np.array([(1.0, 0.92, 0.2), (1.0, 0.4, 0.65), (1.0, 1.0, 1.0), (0.55, 0.45, 1.0)])
    which = (_value_noise(rng, (size, size), (24, 24)) * 4).astype(int).clip(0, 3)
    rgb = _mix(rgb, flowers[which], _smoothstep(0.8, 0.86, speck) * (1 - inner * outside * has_field))

    # the sandy path along z (gently winding), and the round village square
    wind = 1.2 * np.sin(z / 9.0)
    path = 1 - _smoothstep(1.3, 1.8, np.abs(x - wind))
    square = 1 - _smoothstep(6.0, 6.6, np.hypot(x, z))
    cross = (1 - _smoothstep(1.1, 1.6, np.abs(z))) * (np.abs(x) < 22)  # a side street
    sand = _mix((0.86, 0.70, 0.46), (0.74, 0.56, 0.36), fbm(rng, (size, size), (32, 32), 2))
    rgb = _mix(rgb, sand, np.maximum.reduce([path, square, cross]))
    return rgb


# ---- sea ----


def sea(size: int = 256) -> np.ndarray:
    rng = np.random.default_rng(23)
    swell = fbm(rng, (size, size), (4, 8), 4, 0.6)
    glints = _smoothstep(0.72, 0.8, fbm(rng, (size, size), (16, 24), 3))
    rgb = _mix((0.70, 0.92, 0.95), (1.0, 1.0, 1.0), swell)  # multiplies the object's colour
    return _mix(rgb, (1.25, 1.25, 1.2), 0.5 * glints)


if __name__ == "__main__":
    _save("sky.png", sky())
    _save("ground.png", ground(), colors=64)
    _save("sea.png", sea(), colors=32)
