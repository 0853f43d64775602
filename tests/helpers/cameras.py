"""A camera of every projection the painting knows, and the painting's size for each: the cameras the tests of
the projections (``camera.py``) and of the compiled kernels that place a pixel (``engine/kernels``) share."""

from __future__ import annotations

from rcp_server.camera.camera import Camera

EYE = Camera((0.2, 0.1, 0.3), (0.9, 0.0, -2.0), fov=60.0)
CAMERAS = {
    "equirect": EYE.moved(projection="equirect"),
    "perspective top-bottom": EYE.moved(stereo="top-bottom", ipd=0.25),
    "perspective side-by-side": EYE.moved(stereo="side-by-side", ipd=0.25),
    "equirect top-bottom": EYE.moved(projection="equirect", stereo="top-bottom", ipd=0.25),
}
EYE_SIZE = {"equirect": (96, 48), "perspective": (64, 40)}


def painting_size(camera: Camera) -> tuple[int, int]:
    """The painting's size: an eye's image of this projection, both eyes where there are two."""
    return camera.image_size(*EYE_SIZE[camera.projection])
