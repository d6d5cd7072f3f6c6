"""A wide tree's leaves as blocks of 4 triangles (``oclgi.cl.layout.TriBlock4``,
SoA lanes), placed after the tree's nodes in the nodes' buffer, vectorised
numpy.

A leaf of a wide tree (``bvh_wide.py``) is a run of up to 8 triangles of the
scene's BVH-ordered triangle array. Here each run is copied into
ceil(count / 4) consecutive blocks, in the order of the nodes' lanes (a
node's leaves sit together), and the leaf's lane is recoded to point at its
first block: ``~(offset / 32 << 3 | count - 1)``, offset in bytes from the
start of the nodes' buffer (``kernels/bvh.h``; nodes and blocks are 32-byte
multiples). The kernel then tests a leaf 4 triangles at a time
(``kernels/geometry.h`` tri4_intersect, the watertight test lane by lane)
from one contiguous record, without reading the ``Tri`` array.
"""

from __future__ import annotations

import numpy as np

from ..cl.layout import Tri, TriBlock4

LANES = 4
UNIT = 32  # bytes: the granule of a block's offset
LEAF_BITS = 3
MAX_UNIT = (1 << (31 - LEAF_BITS)) - 1


def leaf_blocks(nodes: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nodes with recoded leaf lanes, TriBlock4 records) for the joint node
    array of wide trees (``BvhNode8`` records, leaves as runs of ``tris``,
    the joint ``Tri`` array)."""
    if nodes.itemsize % UNIT or TriBlock4.itemsize % UNIT:
        raise AssertionError("nodes and blocks must be multiples of 32 bytes")
    child = nodes["child"]
    used = np.isfinite(nodes["lox"])
    leaf = used & (child < 0)
    run = ~child[leaf].astype(np.int64)  # row-major: the nodes' order, lane by lane
    first, count = run >> LEAF_BITS, (run & ((1 << LEAF_BITS) - 1)) + 1
    n_blocks = (count + LANES - 1) // LANES
    block0 = np.concatenate([[0], np.cumsum(n_blocks)[:-1]])  # each leaf's first block
    units = (len(nodes) * nodes.itemsize + block0 * TriBlock4.itemsize) // UNIT
    if len(units) and units.max() > MAX_UNIT:
        raise ValueError(f"leaf blocks address at most {MAX_UNIT * UNIT} bytes of nodes")
    out = nodes.copy()
    codes = out["child"]
    codes[leaf] = ~((units << LEAF_BITS) | (count - 1))
    out["child"] = codes

    # every triangle of every leaf: its block and lane
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)  # index within its leaf
    src = np.repeat(first, count) + k
    blk = np.repeat(block0, count) + k // LANES
    lane = k % LANES
    # As 32-bit words: whole Tri rows taken into (block, lane) places, then
    # TriBlock4's fields copied out lane-major, one field at a time (field by
    # field through structured views is ~2-3x slower).
    words = tris.view(np.int32).reshape(len(tris), Tri.itemsize // 4)
    fields = [Tri.fields[f"v{v}"][1] // 4 + axis for v in range(3) for axis in range(3)] + [Tri.fields["id"][1] // 4]
    lanes = np.zeros((int(n_blocks.sum()), LANES, words.shape[1]), np.int32)
    lanes[:, :, fields[-1]] = -1  # unused lanes: id -1
    lanes.reshape(-1, words.shape[1])[blk * LANES + lane] = np.take(words, src, axis=0)
    block_words = np.empty((len(lanes), len(fields), LANES), np.int32)
    for i, f in enumerate(fields):
        block_words[:, i] = lanes[:, :, f]
    blocks = block_words.reshape(len(lanes), -1).view(TriBlock4)[:, 0]
    return out, blocks
