"""What the painting tests share: the image size they paint, and hit points read back from a state."""

import numpy as np
from conftest import CAMERA

from rcp_server.camera.camera import Camera
from rcp_server.painting.loop import PaintState

W, H = 48, 32


def hit_points(state: PaintState, camera: Camera = CAMERA) -> np.ndarray:
    """World hit points from a state that recorded depth and direction (spp = 1): (n, 3) float64."""
    r, u, f = camera.basis()
    direction = state.direction.astype(np.float64)
    along = state.depth.astype(np.float64) / (direction @ f)
    return np.asarray(camera.eye) + along[:, None] * direction
