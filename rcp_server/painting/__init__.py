"""The painting: the tile loop and the methods it runs (traced, fast at rest, image space)."""
