"""An overlap tree (the disc index's binary BVH, after ``boxes.leaf_blocks``)
collapsed into 8-wide nodes for kernels/box_wide.h.

The grouping is the scene tree's (``bvh_wide.wide_levels``: open the inner
child of the largest area until a node has 8 children); only the records
differ. It leaves many nodes just above the leaves with 2 lanes (the
binary depth is rarely a multiple of 3), and a grouping that fills nodes
from the leaves up has a third as many nodes; but it made the walks visit
more of them (Sponza, 10^5 camera discs in leaves of 32, 10^6 photons: 31.1
against 22.5 million node visits), as a segment walks down through the
upper levels that the largest-area order keeps tight. A lane's ``child`` is an inner child's node index (> 0), a leaf's
``~(first << BOX_LEAF_BITS | count - 1)`` (``first`` its first block,
``count`` its primitives), or 0 for an unused lane (box lo = hi = +inf,
masked by the walk). The boxes are the binary nodes' boxes bit for bit, so
the wide walk tests no box a walk of the binary tree would not, and culls
nothing it keeps (kernels/box_wide.h says why).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cl.constants import BOX_LEAF_BITS, BOX_WIDE_STACK
from ..cl.layout import WIDE, BvhNode8
from ..errors import OclgiError
from .bvh_wide import wide_levels

MAX_LEAF = 1 << BOX_LEAF_BITS
MAX_FIRST = (1 << (31 - BOX_LEAF_BITS)) - 1


@dataclass
class WideBoxTree:
    nodes: np.ndarray  # BvhNode8 records, root 0
    depth: int  # levels of wide nodes (root = 1)
    stack_need: int  # the most stack entries a walk writes (kernels/box_wide.h)


def collapse_boxes(nodes: np.ndarray, what: str) -> WideBoxTree:
    """The wide tree of the binary ``nodes`` (BvhNode records whose leaves'
    ``first`` is a block index); ``what`` names the primitives in errors."""
    first = nodes["first"].astype(np.int64)
    count = nodes["count"].astype(np.int64)
    inner = count == 0
    if count.max() > MAX_LEAF:
        raise OclgiError(f"a wide tree's leaf holds at most {MAX_LEAF} {what}, got {int(count.max())} "
                         f"(lower leaf_size)")
    if first[~inner].max() > MAX_FIRST:
        raise OclgiError(f"the wide tree over the {what} addresses at most {MAX_FIRST + 1} blocks")
    levels = wide_levels(nodes)
    starts = np.cumsum([0] + [len(x) for x in levels])
    out = np.zeros(starts[-1], BvhNode8)
    held = np.zeros(starts[-1], np.int64)  # stack entries below each node's visit
    for lvl, lanes in enumerate(levels):
        recs = out[starts[lvl]:starts[lvl + 1]]
        valid = lanes >= 0
        b = np.where(valid, lanes, 0)
        for axis, name in enumerate("xyz"):
            recs["lo" + name] = np.where(valid, nodes["lo"][b, axis], np.float32(np.inf))
            recs["hi" + name] = np.where(valid, nodes["hi"][b, axis], np.float32(np.inf))
        is_inner = valid & inner[b]
        leaf = valid & ~inner[b]
        child = np.zeros(lanes.shape, np.int64)
        child[is_inner] = starts[lvl + 1] + np.arange(int(is_inner.sum()))
        child[leaf] = ~((first[b[leaf]] << BOX_LEAF_BITS) | (count[b[leaf]] - 1))
        recs["child"] = child
        # Every child met is pushed: a child's visit sees its parent's
        # entries plus the parent's other children.
        if lvl + 1 < len(levels):
            below = held[starts[lvl]:starts[lvl + 1]] + valid.sum(axis=1) - 1
            held[starts[lvl + 1]:starts[lvl + 2]] = np.repeat(below, is_inner.sum(axis=1))
    need = int(held.max()) + WIDE
    if need > BOX_WIDE_STACK:  # cannot happen for a tree the binary walk holds (cl/constants.py)
        raise OclgiError(f"the wide tree over the {what} needs {need} stack entries; the walk holds {BOX_WIDE_STACK}")
    return WideBoxTree(nodes=out, depth=len(levels), stack_need=need)
