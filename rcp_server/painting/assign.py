"""Camera assignment, the first stage of an iteration: the mapping turns ``I_{n-1}`` into each pixel's
displacements ``V_p, V_e`` and those into rays (fused in ``kernels.cast_rays``). :class:`TileSetup` holds what
stays fixed over a tile's iterations; :func:`displacements` is the plain numpy form of the fields.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from ..camera.camera import RAY_DTYPE, Camera, Region, pixel_frames, sample_targets
from ..engine import kernels
from ..engine.paintstate import PaintState
from ..settings.mappings import MappingInput, get_mapping
from ..settings.params import PaintParams
from ..util.sampling import noise_vectors, stratified_offsets
from . import fields
from .fields import Looks


@dataclass
class TileSetup:
    """What stays fixed over the iterations of one tile: sample offsets, the noise, the camera's numbers."""

    camera: Camera
    region: Region
    xi: np.ndarray  # (n, spp) float64 sub-pixel offsets
    eta: np.ndarray
    noise: np.ndarray | None  # (n, 3) float32 world-space random vectors, when painting with noise
    image_plane: kernels.ImagePlane = field(init=False)  # the projection and the tile, as the kernels take them

    def __post_init__(self):
        self.image_plane = kernels.ImagePlane.of(self.camera, self.region)

    @functools.cached_property
    def pixels(self) -> np.ndarray:
        """(n,) int64 every pixel of the tile: what an iteration paints (made when first asked: a traced
        iteration counts its own)."""
        return np.arange(self.region.pixel_count)

    def frames(self) -> tuple[np.ndarray, ...]:
        """Each pixel's eye and local frame ``r_ij, u_ij, f_ij``: four (n, 3) float64 (``camera.pixel_frames``)."""
        return pixel_frames(self.camera, self.region, *self.region.pixel_coords())

    def targets(self) -> np.ndarray:
        """``P_p`` of every sample, (n*spp, 3) float64: the numpy form of what cast_rays builds."""
        return sample_targets(self.camera, self.region, *self.region.pixel_coords(), self.xi, self.eta)

    def pitch(self) -> float:
        """``p``: a pixel's size at unit distance (camera.py), what ``lambda_p`` counts in."""
        return self.camera.pixel_pitch(self.image_plane.eye_height)


@functools.lru_cache(maxsize=4)
def _centres(capacity: int) -> np.ndarray:
    """(capacity, 1) float64 0.5: one sample at each pixel's centre, one array that every tile slices (never
    written: offsets are read)."""
    return np.full((capacity, 1), 0.5)


def setup_tile(camera: Camera, region: Region, params: PaintParams) -> TileSetup:
    """The constants of ``region``'s iterations seen by ``camera``: exactly those of the same pixels of the
    full image (counter-based sampling), so a tile is a crop."""
    noisy = any(look.noise for look in params.looks())
    if params.spp == 1 and not noisy:  # the common case needs no pixel coordinates at all
        half = _centres(1 << max(0, region.pixel_count - 1).bit_length())[: region.pixel_count]
        return TileSetup(camera, region, half, half, None)
    i, j = region.pixel_coords()
    xi, eta = stratified_offsets(params.seed, i, j, params.spp)
    noise = None
    if noisy:  # in each pixel's own frame, so that it means the same all around a panorama
        _, r, u, f = pixel_frames(camera, region, i, j)
        v = noise_vectors(params.seed, i, j)
        noise = (v[:, :1] * r + v[:, 1:2] * u + v[:, 2:] * f).astype(np.float32)
    return TileSetup(camera, region, xi, eta, noise)


def displacements(
    state: PaintState,
    setup: TileSetup,
    params: PaintParams,
    z0: float,
    looks: Looks | None = None,
    anchor: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(V_p, V_e)`` per pixel from ``I_{n-1}`` in plain numpy: two (n, 3) float64, scene units
    (``fields.displacements``; ``looks``: the settings per object and material, default only ``params``;
    ``anchor``: where the surface noise is read).

    The reference for what ``kernels.cast_rays`` computes fused; a non-finite displacement moves nothing.
    """
    i, j = setup.region.pixel_coords()
    data = MappingInput.of(state, setup.frames()[1:], z0, i, j)
    return fields.displacements(state, data, looks or Looks.single(params), setup.pitch(), setup.noise, anchor)


@dataclass
class Rays:
    """One tile's buffers for camera assignment, reused over its iterations (a large allocation inside a
    kernel costs more than the kernel)."""

    v_p: np.ndarray  # (n, 3) float64 target displacement per pixel
    v_e: np.ndarray  # (n, 3) float64 eye displacement per pixel
    origins: np.ndarray  # (n*spp, 3) float32
    directions: np.ndarray  # (n*spp, 3) float32

    @classmethod
    def allocate(cls, pixels: int, spp: int) -> Rays:
        rays = pixels * spp
        return cls(
            np.empty((pixels, 3)), np.empty((pixels, 3)), np.empty((rays, 3), RAY_DTYPE), np.empty((rays, 3), RAY_DTYPE)
        )


def cameras(
    state: PaintState,
    setup: TileSetup,
    params: PaintParams,
    z0: float,
    looks: Looks | None = None,
    write_origins: bool = True,
    anchor: np.ndarray | None = None,
) -> kernels.Cast:
    """The tile's cameras from ``I_{n-1}`` as ``kernels.cast_rays`` takes them (``write_origins``: False when the
    eyes rest and the ray buffers already hold the eye). The common case (``Looks.fused``) leaves the fields
    to the kernel; any other is computed here (:func:`displacements`) and given to it as it is."""
    looks = looks or Looks.single(params)
    pitch = setup.pitch()
    moves = not state.blank and state.has(params.reads())
    still = kernels.Field(kernels.FIELD_ZERO, 0.0, kernels.or_dummy(None, 2))
    target, eye_field, noise_scale = still, still, 0.0
    if moves and looks.fused():
        if params.lambda_p != 0.0:
            target = kernels.Field(get_mapping(params.mapping).fused, params.lambda_p * pitch, target.given)
        if params.lambda_e != 0.0:
            eye_field = kernels.Field(get_mapping(params.eye_mapping).fused, params.lambda_e, target.given)
        noise_scale = float(params.noise)
    elif moves:
        v_p, v_e = displacements(state, setup, params, z0, looks, anchor)
        if looks.targets_move:
            target = kernels.Field(kernels.FIELD_GIVEN, 1.0, v_p.astype(np.float32))
        if looks.eyes_move:
            eye_field = kernels.Field(kernels.FIELD_GIVEN, 1.0, v_e.astype(np.float32))
    return kernels.Cast(
        eye=np.asarray(setup.camera.eye, np.float64),
        plane=setup.image_plane,
        xi=setup.xi,
        eta=setup.eta,
        z0=float(z0),
        target=target,
        eye_field=eye_field,
        noise=kernels.or_dummy(setup.noise, 2),
        noise_scale=noise_scale,
        write_origins=write_origins,
    )


def assign_cameras(state: PaintState, setup: TileSetup, params: PaintParams, z0: float, rays: Rays) -> int:
    """Camera assignment alone: fill ``rays`` from ``I_{n-1}`` for every pixel of the tile, sample k of pixel m
    in row m * spp + k. Returns how many rays came out non-finite (they miss). A painting's iteration does this
    inside ``kernels.paint_iteration``."""
    cast = cameras(state, setup, params, z0)
    return kernels.cast_rays(
        **{name: getattr(cast, name) for name in kernels.Cast._fields},
        previous=kernels.channels(state),
        pixels=setup.pixels,
        v_p=rays.v_p,
        v_e=rays.v_e,
        origins=rays.origins,
        directions=rays.directions,
    )
