"""Binned SAH BVH builder (Wald 2007's binning), vectorised numpy.

Top-down, one level of the tree at a time over every node of the level, like
the LBVH builder (``bvh_build.py``), and into the same node layout (``bvh_tree.py``): children
adjacent, nodes numbered level by level, a node's primitives one contiguous
range of the final order. A node splits along the axis and at the bin
boundary that minimise the surface area heuristic

    cost = N_left * area(box_left) + N_right * area(box_right)

over ``BINS`` equal bins of its centroid bounds on each axis. Primitives are
binned by centroid; a bin's box is the union of its primitives' boxes
(``np.minimum.at``/``np.maximum.at`` over node*BINS + bin keys), and the
left and right boxes of every candidate split are prefix and suffix unions
of the bins. The split is a stable partition of the node's range, so the
result depends only on the input boxes: the same tree on every run, thread
count and machine.

A node always splits while it holds more than ``leaf_size`` primitives (the
traversal kernels read leaves of at most that size). Two cases fall back to
halving the range: all centroids coincide (no bin boundary separates them),
and nodes deep enough that SAH's unbalanced splits could outgrow the
traversal stack (``BVH_STACK_SIZE``); there the range is ordered along the
longest centroid axis and cut in the middle, which bounds the depth.
"""

from __future__ import annotations

import numpy as np

from ..cl.constants import BVH_STACK_SIZE, SAH_BINS
from .bvh_tree import BvhData, flatten

BINS = SAH_BINS
# From this depth on, nodes split at the median: a node of n primitives then
# adds at most log2(n / leaf_size) levels, which keeps the deepest leaf
# within the traversal stack for any n up to 2^31.
MEDIAN_DEPTH = BVH_STACK_SIZE - 32


def _area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Half the surface area of boxes given component first, (3, ...); 0 for
    empty boxes (lo > hi)."""
    e = np.maximum(hi - lo, 0.0)
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]


def _scan(op, a: np.ndarray, reverse: bool = False) -> np.ndarray:
    """Inclusive prefix ``op`` (np.minimum, np.maximum) along axis 1, one
    vector op per bin: numpy's ``accumulate`` along a short axis is ~10x slower."""
    out = np.empty_like(a)
    steps = range(a.shape[1] - 1, -1, -1) if reverse else range(a.shape[1])
    prev = None
    for i in steps:
        if prev is None:
            out[:, i] = a[:, i]
        else:
            op(out[:, prev], a[:, i], out=out[:, i])
        prev = i
    return out


def _best_splits(seg, sizes, cen, lo, hi, cmin, cmax, m, n_bins):
    """For each of m nodes: (cost, axis, bin) of the cheapest split, and the
    bin of every primitive along every axis. A split (axis, b) puts bins
    0..b on the left. Cost is inf where no boundary separates the centroids.
    Arrays are component first ((3, rows), (3, m)) and bins bin-major, so
    that every pass runs along contiguous memory."""
    ext = cmax - cmin
    scale = np.where(ext > 0, n_bins / np.where(ext > 0, ext, 1.0), 0.0).astype(np.float32)
    # per-node values spread over the node's rows: np.repeat (rows are node
    # by node) is ~5x faster than indexing a (3, m) array with seg
    bins = np.minimum(((cen - np.repeat(cmin, sizes, axis=1)) * np.repeat(scale, sizes, axis=1)).astype(np.int32),
                      n_bins - 1)
    best_cost = np.full(m, np.inf, np.float32)
    best_axis = np.zeros(m, np.int64)
    best_bin = np.zeros(m, np.int64)
    seg32 = seg.astype(np.int32)
    n_keys = m * n_bins
    blo = np.empty((3, n_keys), np.float32)
    bhi = np.empty((3, n_keys), np.float32)
    for axis in range(3):
        key = bins[axis] * np.int32(m) + seg32  # bin-major: a bin's nodes are contiguous
        count = np.bincount(key, minlength=n_keys).reshape(n_bins, m)
        # the union of each bin's primitive boxes (1-D ufunc.at: ~10x faster than on rows)
        blo.fill(np.inf)
        bhi.fill(-np.inf)
        for k in range(3):
            np.minimum.at(blo[k], key, lo[k])
            np.maximum.at(bhi[k], key, hi[k])
        b_lo, b_hi = blo.reshape(3, n_bins, m), bhi.reshape(3, n_bins, m)
        # left box/count of bins 0..b, right box/count of bins b+1..n_bins-1
        l_area = _area(_scan(np.minimum, b_lo)[:, :-1], _scan(np.maximum, b_hi)[:, :-1])
        r_area = _area(_scan(np.minimum, b_lo, True)[:, 1:], _scan(np.maximum, b_hi, True)[:, 1:])
        n_left = np.cumsum(count, axis=0)[:-1]
        n_right = count.sum(axis=0) - n_left
        cost = n_left * l_area + n_right * r_area
        cost[(n_left == 0) | (n_right == 0)] = np.inf
        b = np.argmin(cost, axis=0)  # the first of equal costs: deterministic
        c = cost[b, np.arange(m)]
        better = c < best_cost  # strict: ties keep the lower axis
        best_cost[better], best_axis[better], best_bin[better] = c[better], axis, b[better]
    return best_cost, best_axis, best_bin, bins


def _segment_ranks(flag: np.ndarray, seg: np.ndarray, seg_first: np.ndarray) -> np.ndarray:
    """For each element, how many elements of its segment before it have ``flag``
    (segments contiguous, ``seg_first[s]`` = index of segment s's first element)."""
    before = np.cumsum(flag) - flag
    return before - before[seg_first[seg]]


def build_sah(box_lo: np.ndarray, box_hi: np.ndarray, leaf_size: int = 4) -> BvhData:
    """Binned SAH BVH over primitive boxes (float32, (n, 3) each)."""
    box_lo = np.asarray(box_lo, dtype=np.float32)
    box_hi = np.asarray(box_hi, dtype=np.float32)
    n = len(box_lo)
    if n == 0:
        raise ValueError("cannot build a BVH over no primitives")
    order = np.arange(n, dtype=np.int64)
    if n <= leaf_size:
        return flatten([np.zeros(1, np.int64)], [np.full(1, n, np.int64)], order, box_lo, box_hi)
    # The working set: the primitives of the nodes still to split, node by
    # node (each node a contiguous run); the primitives of finished leaves
    # leave it for their place in ``order``.
    lo, hi, gid = np.ascontiguousarray(box_lo.T), np.ascontiguousarray(box_hi.T), order.copy()
    cen = (0.5 * (lo.astype(np.float64) + hi)).astype(np.float32)
    sizes = np.array([n], np.int64)  # the working set's nodes: their sizes,
    starts = np.zeros(1, np.int64)  # and their ranges' starts in the final order
    first, count = [np.ones(1, np.int64)], [np.zeros(1, np.int64)]  # root: inner, children 1 and 2
    next_id, level = 1, 0  # next_id: the id of the first node of the next level
    while len(sizes):
        m, rows = len(sizes), len(gid)
        seg = np.repeat(np.arange(m), sizes)
        seg_first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        in_seg = np.arange(rows) - seg_first[seg]
        cmin = np.minimum.reduceat(cen, seg_first, axis=1)
        cmax = np.maximum.reduceat(cen, seg_first, axis=1)
        # Fewer bins where nodes are small: the per-bin arrays stay about the
        # size of the working set (a node of k primitives has k-1 cuts at most).
        n_bins = int(min(BINS, max(4, 1 << int(np.ceil(np.log2(rows / m))))))
        cost, axis, split_bin, bins = _best_splits(seg, sizes, cen, lo, hi, cmin, cmax, m, n_bins)
        left = np.take_along_axis(bins, axis[seg][None], 0)[0] <= split_bin[seg]
        halve = ~np.isfinite(cost) | (level >= MEDIAN_DEPTH)
        if halve.any():
            left = _halve(left, halve, seg, sizes, cen, cmax - cmin)

        # Stable partition of each node's run, its left primitives first: the
        # row now at position i came from src[i].
        n_left = np.add.reduceat(left.astype(np.int64), seg_first)
        rank_l = _segment_ranks(left, seg, seg_first)
        src = np.empty(rows, np.int64)
        src[seg_first[seg] + np.where(left, rank_l, n_left[seg] + in_seg - rank_l)] = np.arange(rows)

        # The next level: the children of these nodes, left then right.
        child_size = np.stack([n_left, sizes - n_left], axis=1).ravel()
        child_start = np.stack([starts, starts + n_left], axis=1).ravel()
        leaf = child_size <= leaf_size
        next_id += 2 * m
        f = np.where(leaf, child_start, 0)
        f[~leaf] = next_id + 2 * np.arange(int((~leaf).sum()))  # numbered as the level after this
        first.append(f)
        count.append(np.where(leaf, child_size, 0))

        # Rows of leaf children take their final place; the others stay.
        child = 2 * seg + (in_seg >= n_left[seg])
        done = leaf[child]
        order[(starts[seg] + in_seg)[done]] = gid[src[done]]
        keep = src[~done]
        # np.take along an axis: ~4x faster than a[:, keep] on (3, rows) arrays
        cen, lo, hi = (np.take(a, keep, axis=1) for a in (cen, lo, hi))
        gid = gid[keep]
        sizes, starts = child_size[~leaf], child_start[~leaf]
        level += 1
    return flatten(first, count, order, box_lo, box_hi)


def _halve(left, halve, seg, sizes, cen, ext):
    """``left`` with the nodes marked in ``halve`` cut in the middle of their
    range ordered along their longest centroid axis (index order on ties)."""
    rows = np.nonzero(halve[seg])[0]
    node = seg[rows]
    key = cen[np.argmax(ext, axis=0)[node], rows]
    by = np.lexsort((rows, key, node))  # node, then centroid, then position
    rank = np.empty(len(rows), np.int64)
    rank[by] = np.arange(len(rows))
    # rank within the node = rank among the rows - rows of earlier halved nodes
    node_start = np.searchsorted(node, node, side="left")  # rows are node-sorted
    left = left.copy()
    left[rows] = (rank - node_start) < sizes[node] // 2
    return left
