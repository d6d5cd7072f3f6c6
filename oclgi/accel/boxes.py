"""Boxes of discs and of segment pieces for the overlap trees, rounded so
that float32 never shrinks them, and the leaf blocks the device walks read
(kernels/box_bvh.h). Shared by the disc index, the ray map and the Photon
Map session's ball tree.
"""

from __future__ import annotations

import numpy as np

from ..cl.constants import BOX_BVH_STACK, LANES
from ..errors import OclgiError

# Box pad, relative to the scene's coordinate scale (why: estimators/detp_disc_index.py).
PAD = 2e-5


def column_bounds(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each column's min and max of an (n, k) array (n > 0). numpy reduces
    an (n, 3) array along axis 0 with a 3-wide inner loop per row: 30x
    slower than reducing the transposed copy's rows (260 against 9 us for
    4,000 rows). min and max are exact, so the values are the same."""
    t = np.ascontiguousarray(np.asarray(a).T)
    return t.min(axis=1), t.max(axis=1)


# which of a box's 8 corners take hi on each axis (x slowest, z fastest)
_CORNER_HI = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], bool)


def box_corners(lo, hi) -> np.ndarray:
    """The 8 corners (float64, (..., 8, 3)) of boxes lo, hi of shape (..., 3)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    return np.where(_CORNER_HI, hi[..., None, :], lo[..., None, :])


def coordinate_scale(compiled, positions: np.ndarray) -> float:
    """Largest of the scene's diagonal and its (and the points') coordinates:
    float32 rounding is relative to the coordinates, not to the extent."""
    lo, hi = compiled.bounds
    if len(positions):
        p_lo, p_hi = column_bounds(positions)
        lo, hi = np.minimum(lo, p_lo), np.maximum(hi, p_hi)
    return float(max(np.linalg.norm(hi - lo), np.abs(lo).max(), np.abs(hi).max(), 1e-30))


def outward_f32(lo: np.ndarray, hi: np.ndarray):
    """float64 boxes rounded outward to float32 (never shrink a box)."""
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32, hi32


def active_discs(points):
    """Ids of the points whose normal is not zero (the others never count)."""
    return np.nonzero((points.normals[:, :3] != 0).any(axis=1))[0]


def disc_boxes(positions: np.ndarray, normals: np.ndarray, radius, pad: float):
    """Padded float32 boxes of the discs: half-extent d sqrt(1 - n_a^2) + pad
    (``radius`` d one number, or one per disc)."""
    n = normals.astype(np.float64)
    n /= np.linalg.norm(n, axis=1)[:, None]
    radius = np.asarray(radius, np.float64)
    if radius.ndim:
        radius = radius[:, None]
    half = radius * np.sqrt(np.clip(1.0 - n * n, 0.0, 1.0)) + pad
    x = positions.astype(np.float64)
    return outward_f32(x - half, x + half)


def leaf_blocks(nodes: np.ndarray, n_prims: int):
    """Blocks of LANES (float8 lanes) primitives per leaf: rewrites each leaf's ``first`` to
    its first block; returns (nodes, block of each primitive, lane of each
    primitive, number of blocks), primitives numbered in leaf order."""
    nodes = nodes.copy()
    leaves = np.nonzero(nodes["count"] > 0)[0]
    leaves = leaves[np.argsort(nodes["first"][leaves], kind="stable")]
    first = nodes["first"][leaves].astype(np.int64)
    count = nodes["count"][leaves].astype(np.int64)
    nblk = (count + LANES - 1) // LANES
    blk0 = np.zeros(len(leaves), np.int64)
    np.cumsum(nblk[:-1], out=blk0[1:])
    leaf_of = np.repeat(np.arange(len(leaves)), count)  # leaves tile [0, n_prims) in order
    k = np.arange(n_prims) - first[leaf_of]
    nodes["first"][leaves] = blk0
    return nodes, blk0[leaf_of] + k // LANES, k % LANES, int(nblk.sum())


def check_depth(depth: int, what: str):
    """The device walk (kernels/box_bvh.h) holds depth + 1 entries."""
    if depth + 1 > BOX_BVH_STACK:
        raise OclgiError(f"the BVH over the {what} is {depth} levels deep; the device walk holds {BOX_BVH_STACK - 1}")
