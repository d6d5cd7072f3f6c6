"""The flattened BVH both builders produce (``bvh_build.py``'s LBVH,
``bvh_sah.py``'s binned SAH): nodes numbered level by level, root 0,
children of an inner node adjacent, a leaf's primitives one contiguous run
of the primitive order (``oclgi.cl.layout.BvhNode``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cl.layout import BvhNode


@dataclass
class BvhData:
    nodes: np.ndarray  # BvhNode records
    order: np.ndarray  # primitive ids in leaf order
    depth: int  # number of levels (root = 1)


def flatten(first: list, count: list, order: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray) -> BvhData:
    """The node array of a tree given level by level: ``first[l]``/``count[l]``
    for the nodes of level l (an inner node's first child and count 0, or a
    leaf's first primitive in ``order`` and its count); boxes are reduced
    bottom-up from the primitives' float32 boxes, so they bound exactly."""
    first_all = np.concatenate(first)
    count_all = np.concatenate(count)
    n_nodes = len(first_all)
    lo = np.empty((n_nodes, 3), np.float32)
    hi = np.empty((n_nodes, 3), np.float32)
    # leaves: reduce the sorted primitive boxes over their ranges (leaves tile [0, n))
    leaf = count_all > 0
    leaf_ids = np.nonzero(leaf)[0]
    leaf_ids = leaf_ids[np.argsort(first_all[leaf_ids], kind="stable")]
    slo, shi = box_lo[order], box_hi[order]
    lo[leaf_ids] = np.minimum.reduceat(slo, first_all[leaf_ids], axis=0)
    hi[leaf_ids] = np.maximum.reduceat(shi, first_all[leaf_ids], axis=0)
    # inner nodes, deepest level first
    level_start = np.cumsum([0] + [len(x) for x in first])
    for lvl in range(len(first) - 1, -1, -1):
        ids = np.arange(level_start[lvl], level_start[lvl + 1])
        ids = ids[count_all[ids] == 0]
        if len(ids) == 0:
            continue
        c0 = first_all[ids]
        lo[ids] = np.minimum(lo[c0], lo[c0 + 1])
        hi[ids] = np.maximum(hi[c0], hi[c0 + 1])

    nodes = np.zeros(n_nodes, dtype=BvhNode)
    # + 0: a zero bound is +0.0 whichever of -0.0 and 0.0 the reductions met
    # first, so that every builder's boxes are the same bytes (bvh_sah_device.py)
    nodes["lo"], nodes["hi"] = lo + np.float32(0), hi + np.float32(0)
    nodes["first"], nodes["count"] = first_all, count_all
    return BvhData(nodes=nodes, order=order, depth=len(first))
