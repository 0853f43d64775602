"""Painting on a Ray cluster."""
