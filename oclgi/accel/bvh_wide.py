"""The scene's wide BVH: a binary tree (``bvh_tree.py``, from either builder)
collapsed into 8-wide nodes (``oclgi.cl.layout.BvhNode8``), vectorised numpy.

One canonical build, converted into the traversal layout: the binary tree
stays the tree that is built and tested for quality; this module only
regroups its nodes. A wide node starts from one inner binary node's two
children and repeatedly opens the inner child of the largest surface area
(the one a random ray is likeliest to enter), replacing it by its two
children, until it has 8 children or only leaves. Every inner child then
becomes a wide node of the next level. The boxes are the binary nodes'
boxes bit for bit, and the leaves are the binary leaves (the same triangle
runs), so a ray meets the same triangles in the same leaf order; only the
order of the leaves differs (nearest child first in both).

All wide nodes of a level are collapsed together, one vector pass per
opening (6 at most per level). Ties in area open the lowest lane; the
result depends on the binary tree alone, like the builders' (deterministic).

Nodes are numbered level by level, root 0. A lane's ``child`` is the index
of an inner child's node, or ``~(first_tri << 3 | (count - 1))`` for a leaf
(negative); unused lanes have the box lo = hi = +inf, which no ray enters
(``kernels/bvh.h``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cl.constants import BVH_STACK_SIZE
from ..cl.layout import WIDE, BvhNode8

# The wide traversal's stack (kernels/bvh.h BVH_WIDE_STACK, which derives it
# the same way): a wide node pushes up to WIDE - 1 children and stores a
# whole vector of WIDE entries, so it needs more room than the binary walk.
WIDE_STACK = 2 * BVH_STACK_SIZE
# Leaf runs are packed with their count in the low 3 bits of the lane.
LEAF_BITS = 3
MAX_LEAF = 1 << LEAF_BITS
MAX_FIRST_TRI = (1 << (31 - LEAF_BITS)) - 1


@dataclass
class WideData:
    nodes: np.ndarray  # BvhNode8 records
    depth: int  # levels of wide nodes (root = 1)
    stack_need: int  # the deepest stack a traversal of this tree uses (entries)


def _half_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    e = np.maximum(hi.astype(np.float64) - lo, 0.0)
    return e[:, 0] * e[:, 1] + e[:, 1] * e[:, 2] + e[:, 2] * e[:, 0]


def wide_levels(nodes: np.ndarray, width: int = WIDE) -> list[np.ndarray]:
    """The grouping of the binary tree ``nodes`` (root 0) into wide nodes,
    level by level: per level an (m, WIDE) array of the binary nodes in each
    wide node's lanes (-1: unused), the next level's wide nodes being the
    inner lanes in row-major order. Any tree whose inner nodes have their
    children at first and first + 1 (kernels/box_bvh.h's overlap trees too)."""
    if not 2 <= width <= WIDE:
        raise ValueError(f"a wide node has 2 to {WIDE} children, got {width}")
    first = nodes["first"].astype(np.int64)
    inner = nodes["count"] == 0
    if not inner.any():  # a single leaf: one wide node with one lane
        return [np.array([[0] + [-1] * (WIDE - 1)], np.int64)]
    levels = []
    area = _half_area(nodes["lo"], nodes["hi"])
    roots = np.zeros(1, np.int64)  # binary inner nodes that become this level's wide nodes
    while len(roots):
        m = len(roots)
        lanes = np.full((m, WIDE), -1, np.int64)
        lanes[:, 0], lanes[:, 1] = first[roots], first[roots] + 1
        used = np.full(m, 2, np.int64)
        rows = np.arange(m)
        for _ in range(width - 2):
            valid = lanes >= 0
            openable = valid & inner[np.where(valid, lanes, 0)]
            score = np.where(openable, area[np.where(valid, lanes, 0)], -1.0)
            pick = np.argmax(score, axis=1)  # the first of equal areas
            grow = (used < width) & openable.any(axis=1)
            if not grow.any():
                break
            r, k = rows[grow], pick[grow]
            b = lanes[r, k]
            lanes[r, k] = first[b]
            lanes[r, used[r]] = first[b] + 1
            used[r] += 1
        levels.append(lanes)
        valid = lanes >= 0
        roots = lanes[valid & inner[np.where(valid, lanes, 0)]]  # row-major: the next level's order
    return levels


def collapse(nodes: np.ndarray, node_offset: int = 0, tri_offset: int = 0, width: int = WIDE) -> WideData:
    """Wide nodes of the binary tree ``nodes`` (``BvhNode`` records, root 0,
    leaves of at most 8 triangles); child indices get ``node_offset`` added
    and triangle runs ``tri_offset`` (the object's place in the scene's joint
    arrays). ``width`` (2 to WIDE) caps the children of a node: fewer lanes
    used, for measuring narrower trees in the same layout."""
    first = nodes["first"].astype(np.int64)
    count = nodes["count"].astype(np.int64)
    inner = count == 0
    if count.max() > MAX_LEAF:
        raise ValueError(f"a wide node's leaf holds at most {MAX_LEAF} triangles, got {int(count.max())}")
    levels = wide_levels(nodes, width)

    # Number the wide nodes level by level and fill the records.
    sizes = [len(x) for x in levels]
    starts = np.cumsum([0] + sizes)
    out = np.zeros(starts[-1], dtype=BvhNode8)
    need = np.zeros(starts[-1], np.int64)  # stack entries held below each node's visit
    lo, hi = nodes["lo"], nodes["hi"]
    for lvl, lanes in enumerate(levels):
        recs = out[starts[lvl]:starts[lvl + 1]]
        valid = lanes >= 0
        b = np.where(valid, lanes, 0)
        for axis, name in enumerate("xyz"):
            recs["lo" + name] = np.where(valid, lo[b, axis], np.float32(np.inf))
            recs["hi" + name] = np.where(valid, hi[b, axis], np.float32(np.inf))
        is_inner = valid & inner[b]
        child = np.full(lanes.shape, -1, np.int64)
        child[is_inner] = node_offset + starts[lvl + 1] + np.arange(int(is_inner.sum()))
        leaf = valid & ~inner[b]
        run = first[b[leaf]] + tri_offset
        if len(run) and run.max() > MAX_FIRST_TRI:
            raise ValueError(f"wide leaves address at most {MAX_FIRST_TRI + 1} triangles")
        child[leaf] = ~((run << LEAF_BITS) | (count[b[leaf]] - 1))
        recs["child"] = child
        # A visit stores a whole vector at the stack's top and keeps the
        # lanes hit but the nearest: children see their parent's entries
        # plus its lanes - 1.
        if lvl + 1 < len(levels):
            held = need[starts[lvl]:starts[lvl + 1]] + valid.sum(axis=1) - 1
            need[starts[lvl + 1]:starts[lvl + 2]] = np.repeat(held, is_inner.sum(axis=1))
    return WideData(nodes=out, depth=len(levels), stack_need=int(need.max()) + WIDE)
