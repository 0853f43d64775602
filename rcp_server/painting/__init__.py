"""The painting: the tile loop and the methods it runs (traced, image space)."""
