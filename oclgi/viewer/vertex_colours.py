"""What the page draws at each vertex, and the frames that bring it up to date.

A vertex's colour is its outgoing radiance, linear RGB:
``L = Le + rho * E / pi`` with ``rho`` the diffuse part of its source
triangle's material (Material.diffuse_albedo) and ``Le`` its emission; the
page applies the exposure and sRGB. Textures and mesh vertex colours are
not sampled: a textured surface shows its material's albedo (the solution
itself, the irradiance, does not depend on that choice).

A frame carries only what the page does not have yet: the vertices whose
colour differs from the last frame sent (their indices and values), or the
whole array when more than half changed (an index costs as much as a
colour channel). Layout, little-endian:

    b"OGVC", uint32 seq, uint32 mode (FULL 0 | SPARSE 1), uint32 count,
    SPARSE: uint32 index[count], float32 rgb[count][3]
    FULL:   float32 rgb[count][3]          (count = the number of vertices)
"""

from __future__ import annotations

import math
import struct

import numpy as np

MAGIC = b"OGVC"
FULL, SPARSE = 0, 1
HEADER = struct.Struct("<4sIII")


def vertex_terms(scene, vertex_tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rho / pi, Le) per vertex, float32 (V, 3), from each vertex's source triangle's material."""
    mats = scene.materials
    reflect = np.array([m.diffuse_albedo for m in mats], np.float64) / math.pi
    emit = np.array([m.emission for m in mats], np.float64)
    mat = np.asarray(scene.tri_material)[vertex_tri]
    return reflect[mat].astype(np.float32), emit[mat].astype(np.float32)


def radiance(irradiance: np.ndarray, terms: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Outgoing radiance (V, 3) float32 from the per-vertex irradiance."""
    reflect, emit = terms
    return (emit + reflect * np.asarray(irradiance, np.float32)).astype(np.float32)


class FrameEncoder:
    """The colours the page has, and the frame that brings it to new ones."""

    def __init__(self, n_vertices: int):
        self.sent = None  # what the page has (None: nothing yet)
        self.n = n_vertices

    def frame(self, colours: np.ndarray, seq: int) -> bytes | None:
        """The frame from the colours sent to ``colours`` (None when nothing
        changed); ``colours`` become the colours sent."""
        colours = np.ascontiguousarray(colours, np.float32)
        if self.sent is None:
            changed = np.arange(self.n)
        else:
            changed = np.nonzero((colours != self.sent).any(axis=1))[0]
            if not len(changed):
                return None
        self.sent = colours.copy()
        if 2 * len(changed) > self.n:
            return HEADER.pack(MAGIC, seq, FULL, self.n) + colours.tobytes()
        return (HEADER.pack(MAGIC, seq, SPARSE, len(changed)) + changed.astype("<u4").tobytes()
                + colours[changed].tobytes())
