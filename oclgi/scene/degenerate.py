"""Which triangles are degenerate, judged by each triangle's own shape.

The device stores vertices in float32 and computes a triangle's edges and
normal from them, so a triangle is judged as it will be seen there: after
rounding its vertices to float32. It is degenerate when its normal is noise
at that precision: the cross product of two edges (the normal the
intersection test computes) is not finite or has no normal float32 component
(it would flush to zero, and the ray-plane distance divide by it), or it is
shorter than a few float32 rounding steps of the
square of the triangle's longest edge (a sliver: twice its area against its
longest edge squared is below ``MIN_SHAPE``).

The test is relative to each triangle alone, so a scene's other geometry
never decides: a 200 km ground plane added to a room keeps the room's
0.16 m^2 light.
"""

from __future__ import annotations

import numpy as np

# 2 * area / longest_edge^2 of the thinnest triangle kept: 8 float32 steps
# (2^-23 each). An equilateral triangle has 0.87; a 1 m x 1 um one 1e-6.
MIN_SHAPE = 2.0**-20
_F32_TINY = float(np.finfo(np.float32).tiny)


def degenerate_triangles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: True for each face of ``faces`` into ``vertices`` that is degenerate."""
    v = np.asarray(vertices, dtype=np.float32)[faces]  # (F, 3, 3), as the device holds them
    with np.errstate(over="ignore", invalid="ignore"):
        e1 = v[:, 1] - v[:, 0]
        e2 = v[:, 2] - v[:, 0]
        n = np.cross(e1, e2)  # float32, as the device computes it
        edges = np.stack([e1, e2, v[:, 2] - v[:, 1]], axis=1).astype(np.float64)
        longest2 = (edges * edges).sum(axis=2).max(axis=1)
        twice_area = np.linalg.norm(n.astype(np.float64), axis=1)
        ok = (np.isfinite(n).all(axis=1) & (np.abs(n).max(axis=1) >= _F32_TINY)
              & (twice_area > MIN_SHAPE * longest2))
    return ~ok
