"""The camera: projections, per-pixel frames and the camera on the wire."""
