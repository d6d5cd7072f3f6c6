"""Scenes: mesh loading, materials, emitters, camera, and the TOML/dict description."""
