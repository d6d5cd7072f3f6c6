"""Acceleration structures: the BVH builder (host) and its device form."""
