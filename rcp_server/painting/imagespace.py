"""The image-space variant (paper section 6, the game-engine route): with ``V_e = 0`` a displaced target
``P_p' = P_p + V_p`` is seen along a primary ray of the same eye, so instead of tracing it we look up the
plain render where that ray crosses the image plane.

Pixel coordinates here are continuous, with pixel centres on the integers: pixel ``(i, j)`` covers
``[i - 0.5, i + 0.5) x [j - 0.5, j + 0.5)`` (so ``x = s W - 0.5``, ``y = t H - 0.5`` with ``s, t`` the
texture coordinates of ``camera.py``). A lookup is bilinear between the four nearest pixel centres.

Off screen, an integer pixel index ``k`` of a row of ``n`` pixels is mapped back by the edge mode:

* ``clamp``: ``min(max(k, 0), n - 1)`` (the edge pixel repeats: bars of color);
* ``wrap``: ``k mod n`` (the opposite edge: a seam where the two edges differ);
* ``mirror``: ``k mod 2n`` reflected, ``2n - 1 - k`` for ``k >= n`` (the edge pixel repeats once,
  then the image runs backwards: the paper's choice, and the default).

A pixel whose displaced target is not in front of the eye (``(P_p' - eye) . f <= 0``: it has no
projection) or whose offset is not finite keeps its own plain value. ``kernels.look_up`` is the
compiled pass the painting runs (:class:`LookupTile`); :func:`lookup_coords` and :func:`bilinear` are
its plain numpy form (the tests check that they agree).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from ..camera.camera import Camera, Region, directions_at, eye_pixels, project
from ..engine import kernels
from ..engine.paintstate import PaintState, TileIteration
from ..settings.params import EDGES, PaintParams
from ..util.stopwatch import Stopwatch
from .assign import TileSetup, cameras, setup_tile
from .fields import Looks


def lookup_coords(v_p: np.ndarray, camera: Camera, region: Region) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each pixel's displaced target ``P_p' = P_p + V_p`` is seen from its eye (``camera.project``).

    v_p : (n, 3) float64 target displacement of each pixel of ``region`` (at its centre), scene units.
    Returns ``x, y`` (n,) float64 continuous pixel coordinates of the eye's image, and ``ok`` (n,) bool:
    False where ``P_p'`` cannot be projected (behind a perspective eye) or a coordinate is not finite; there
    ``x, y`` are the pixel's own centre, so that pixel keeps its own plain value. On the sphere ``x`` goes
    the shorter way round, and may leave ``[0, W)`` by up to half a turn.

    ``V_p = 0`` gives exactly the pixel's own integer coordinates: the offset is computed, not the position.
    """
    i, j = region.pixel_coords()
    side, ei, ej = eye_pixels(camera, region, i, j)
    centre, *_ = directions_at(camera, region, ei + 0.5, ej + 0.5)
    mono = np.zeros_like(side)
    ax, ay, ok_a = project(camera, region, mono, centre + v_p)
    bx, by, ok_b = project(camera, region, mono, centre)
    ok = ok_a & ok_b
    dx, dy = np.where(ok, ax - bx, 0.0), np.where(ok, ay - by, 0.0)
    if camera.projection == "equirect":
        width = camera.eye_size(region.full_width, region.full_height)[0]
        dx = (dx + 0.5 * width) % width - 0.5 * width
    return ei + dx, ej + dy, ok


def _reduce(coord: np.ndarray, n: int, edge: str) -> np.ndarray:
    """Bring a coordinate into a range where its integer neighbours fit int64, without changing the lookup:
    clamp is constant beyond [0, n - 1], wrap and mirror are periodic with period n and 2n."""
    if edge == "clamp":
        return np.clip(coord, -1.0, float(n))
    if edge == "wrap":
        return np.mod(coord, float(n))
    return np.mod(coord, 2.0 * n)


def edge_index(k: np.ndarray, n: int, edge: str) -> np.ndarray:
    """Integer pixel indices ``k`` (any int64) mapped into ``[0, n)`` by the edge mode (module docstring)."""
    if edge == "clamp":
        return np.clip(k, 0, n - 1)
    if edge == "wrap":
        return np.mod(k, n)
    if edge == "mirror":
        k = np.mod(k, 2 * n)
        return np.where(k >= n, 2 * n - 1 - k, k)
    raise ValueError(f"unknown edge mode {edge!r}; choose one of {', '.join(EDGES)}")


def sphere_index(c: np.ndarray, r: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel indices of a panorama, a row past a pole at most: longitude wraps, and a row past a pole is the row
    on its other side, half a turn around (``kernels.lookup`` does the same)."""
    over = (r < 0) | (r >= height)
    r = np.where(r < 0, -1 - r, np.where(r >= height, 2 * height - 1 - r, r))
    return np.mod(np.where(over, c + width // 2, c), width), r


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray, edge: str) -> np.ndarray:
    """Bilinear lookup of ``image`` (h, w) or (h, w, c) at continuous pixel coordinates ``x, y`` ((n,)
    float64, centres on the integers), off-screen indices mapped by ``edge`` (or ``"sphere"``: a panorama, where
    longitude wraps and the poles mirror). Returns (n,) or (n, c) in float64; an integer ``(x, y)`` returns
    that pixel's value exactly."""
    h, w = image.shape[:2]
    if edge == "sphere":
        x = np.mod(x, float(w))
        y = np.clip(y, -0.5, h - 0.5)
    else:
        x = _reduce(x, w, edge)
        y = _reduce(y, h, edge)
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = x - x0
    fy = y - y0
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    if image.ndim == 3:
        fx = fx[:, None]
        fy = fy[:, None]
    if edge == "sphere":
        corners = [sphere_index(x0 + dc, y0 + dr, w, h) for dr in (0, 1) for dc in (0, 1)]
        (c00, r00), (c01, r01), (c10, r10), (c11, r11) = corners
        top = image[r00, c00] * (1.0 - fx) + image[r01, c01] * fx
        bottom = image[r10, c10] * (1.0 - fx) + image[r11, c11] * fx
        return top * (1.0 - fy) + bottom * fy
    c0, c1 = edge_index(x0, w, edge), edge_index(x0 + 1, w, edge)
    r0, r1 = edge_index(y0, h, edge), edge_index(y0 + 1, h, edge)
    top = image[r0, c0] * (1.0 - fx) + image[r0, c1] * fx
    bottom = image[r1, c0] * (1.0 - fx) + image[r1, c1] * fx
    return top * (1.0 - fy) + bottom * fy


class LookupTile:
    """One image-space iteration of the tile ``setup`` describes (a ``paintstate.TileIteration``):
    ``I_{n-1} -> I_n``, each pixel looking up ``plain`` (the full frame's plain render, every recorded channel)
    where its displaced target projects, one bilinear lookup per pixel at its centre (samples per pixel only
    antialias the plain render).

    Stages: "camera" is the displacement, "shade" the projection and lookup. A state that cannot move a
    pixel (the canvas, a missing channel) leaves it its plain value. ``looks``: the settings per object and
    material (``fields.Looks``), as the traced method takes them.
    """

    def __init__(self, plain: PaintState, setup: TileSetup, params: PaintParams, looks: Looks | None = None):
        self.plain, self.setup, self.params, self.looks = plain, setup, params, looks
        self.z0 = params.focus(setup.camera)
        self.edge = EDGES.index(params.edge)
        self.v_p = np.zeros((setup.region.pixel_count, 3))
        self.anchor = plain.rows(setup.region).position  # the surface noise is read on the plain render's points

    def __call__(self, state: PaintState, watch: Stopwatch) -> PaintState:
        setup, plain = self.setup, self.plain
        with watch.stage("camera"):
            # V_p, the same fields as the traced method
            cast = cameras(state, setup, self.params, self.z0, self.looks, anchor=self.anchor)
            field = cast.target
            if field.kind != kernels.FIELD_ZERO:
                kernels.fill_field(
                    field=field,
                    plane=setup.image_plane,
                    previous=kernels.channels(state),
                    z0=float(self.z0),
                    noise=cast.noise,
                    noise_scale=cast.noise_scale,
                    pixels=setup.pixels,
                    out=self.v_p,
                )
        with watch.stage("shade"):
            # every recorded channel, where the displaced ray crosses the image plane
            new = PaintState.empty(setup.region, plain.recorded())
            kernels.look_up(
                v_p=self.v_p,
                moves=field.kind != kernels.FIELD_ZERO,
                plane=setup.image_plane,
                edge=self.edge,
                plain=kernels.channels(plain),
                out=kernels.channels(new),
            )
        return new


class LookupTiles:
    """The image-space method's evaluator (``loop.Tiles``): each tile's iterations look up ``plain``."""

    def __init__(self, plain: PaintState, camera: Camera, params: PaintParams, looks: Looks):
        self.plain, self.camera, self.params, self.looks = plain, camera, params, looks

    @contextmanager
    def lend(self, tile: Region, reads: PaintState | None) -> Iterator[TileIteration]:
        yield LookupTile(self.plain, setup_tile(self.camera, tile, self.params), self.params, self.looks)
