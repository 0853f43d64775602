"""Utilities every layer may use: seeded sampling, stopwatches, image encoding, CLI argument types."""
