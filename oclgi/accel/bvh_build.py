"""Linear BVH builder (Morton order, Karras-style splits), vectorised numpy.

The builder sees only primitive boxes: it returns the flattened nodes and the
primitive order, and the caller permutes its primitives (triangles now,
instances in a top level later). Primitives are sorted by the 30-bit Morton
code of their box centre; a node over a sorted range splits where the highest
bit that differs across the range flips (the middle when all codes are
equal), until at most ``leaf_size`` primitives remain. The tree is built one
level at a time over all nodes of the level, so the cost is a sort plus
O(depth) vector passes: about a second for a million triangles.

Node layout (``oclgi.cl.layout.BvhNode``): children of an inner node are
adjacent, nodes are numbered level by level, root 0.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .boxes import column_bounds
from .bvh_sah import build_sah
from .bvh_sah_device import DEVICE_MIN_PRIMITIVES, build_sah_device
from .bvh_tree import BvhData, flatten


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """10-bit integers -> every third bit of a 30-bit word."""
    x = x.astype(np.uint64) & 0x3FF
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    x = (x | (x << 2)) & 0x09249249
    return x


def morton_codes(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    ext = np.maximum(hi - lo, 1e-30)
    q = np.clip(((points - lo) / ext * 1024.0).astype(np.int64), 0, 1023)
    return (_spread_bits(q[:, 0]) << 2) | (_spread_bits(q[:, 1]) << 1) | _spread_bits(q[:, 2])


def bit_length(x: np.ndarray) -> np.ndarray:
    """Exact bit length of uint64 values (float64 alone rounds above 2^53)."""
    hi = (x >> np.uint64(32)).astype(np.float64)
    lo = (x & np.uint64(0xFFFFFFFF)).astype(np.float64)
    return np.where(hi > 0, 32 + np.frexp(hi)[1], np.frexp(lo)[1]).astype(np.int64)


# The builders of binary trees.
BUILDERS = ("lbvh", "sah")
# The scene trees (oclgi/scene/compiled.py): "lbvh" and "sah", a builder's
# binary tree traversed as built, and "sah8b", the SAH tree collapsed into
# 8-wide nodes (bvh_wide.py), which the scene's traversal slabs 8 boxes at a
# time, with its leaves as blocks of 4 triangles tested at once
# (bvh_leaf_blocks.py).
QUALITIES = ("lbvh", "sah", "sah8b")


class SceneTree(NamedTuple):
    builder: str  # of BUILDERS
    wide: bool  # 8-wide nodes, leaves as TriBlock4 records


def scene_tree(quality: str) -> SceneTree:
    """What a scene tree name of QUALITIES builds."""
    if quality not in QUALITIES:
        raise ValueError(f"BVH quality must be one of {QUALITIES}, got {quality!r}")
    return SceneTree(quality.partition("8")[0], "8" in quality)


def build_bvh(box_lo: np.ndarray, box_hi: np.ndarray, leaf_size: int = 4, quality: str = "lbvh",
              queue=None) -> BvhData:
    """A binary BVH over primitive boxes: ``quality="lbvh"`` splits on the
    30-bit Morton codes of their centres (fast; the overlap trees use it),
    ``"sah"`` by the binned surface area heuristic (``bvh_sah.py``; better
    trees for ray traversal). Given an OpenCL ``queue``, a SAH tree over at
    least ``DEVICE_MIN_PRIMITIVES`` boxes is built on its device
    (``bvh_sah_device.py``: the same tree, bit for bit, faster); without
    one, or below that size, by the numpy builder."""
    if quality == "sah":
        if queue is not None and len(box_lo) >= DEVICE_MIN_PRIMITIVES:
            return build_sah_device(queue, box_lo, box_hi, leaf_size)
        return build_sah(box_lo, box_hi, leaf_size)
    if quality != "lbvh":
        raise ValueError(f"BVH quality must be one of {BUILDERS}, got {quality!r}")
    box_lo = np.asarray(box_lo, dtype=np.float32)
    box_hi = np.asarray(box_hi, dtype=np.float32)
    if len(box_lo) == 0:
        raise ValueError("cannot build a BVH over no primitives")
    centres = 0.5 * (box_lo.astype(np.float64) + box_hi)
    return build_from_codes(morton_codes(centres, *column_bounds(centres)), box_lo, box_hi, leaf_size)


def build_from_codes(codes: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray, leaf_size: int) -> BvhData:
    """LBVH over primitive boxes (float32) ordered by the given uint64 codes
    (any width: the 30-bit codes above, or the photon map's 63-bit ones).
    Ties keep id order and split in the middle."""
    n = len(codes)
    order = np.argsort(codes, kind="stable")
    codes = codes[order]

    # Level by level: (start, end) ranges of the nodes of the current level.
    first = [np.zeros(1, np.int64)]  # per level: child index or first primitive
    count = [np.zeros(1, np.int64)]
    starts, ends = np.zeros(1, np.int64), np.full(1, n, np.int64)
    next_id = 1
    while True:
        size = ends - starts
        inner = size > leaf_size
        f = starts.copy()
        c = size.copy()
        n_inner = int(inner.sum())
        if n_inner == 0:
            first[-1], count[-1] = f, c
            break
        s, e = starts[inner], ends[inner]
        diff = codes[s] ^ codes[e - 1]
        split = (s + e) // 2  # equal codes: the middle
        nz = diff != 0
        if nz.any():  # first index whose code has the highest differing bit set
            bit = (bit_length(diff[nz]) - 1).astype(np.uint64)
            target = ((codes[s[nz]] >> bit) | np.uint64(1)) << bit
            split[nz] = np.searchsorted(codes, target, side="left")
        child = next_id + 2 * np.arange(n_inner)
        f[inner] = child
        c[inner] = 0
        first[-1], count[-1] = f, c
        next_id += 2 * n_inner
        starts = np.empty(2 * n_inner, np.int64)
        ends = np.empty(2 * n_inner, np.int64)
        starts[0::2], ends[0::2] = s, split
        starts[1::2], ends[1::2] = split, e
        first.append(None)
        count.append(None)

    return flatten(first, count, order, box_lo, box_hi)
