"""Painting settings: the parameters, the mappings that displace cameras, and the styles."""
