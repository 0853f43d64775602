"""The engine: the Embree binding, the compiled kernels and the painting's per-pixel state."""
