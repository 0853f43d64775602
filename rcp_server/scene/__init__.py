"""Scenes: meshes, glTF, environments, scene files, framing, and the sandbox for untrusted uploads."""
