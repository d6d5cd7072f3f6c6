"""Binned SAH BVH builder on the OpenCL device: ``bvh_sah.py``'s tree, bit for bit.

The numpy builder (``bvh_sah.py``) is the specification and the tests'
oracle; this one runs its per-primitive work in ``kernels/bvh_sah_device.cl``
and keeps the per-node bookkeeping (node numbering, children, leaves) here,
in the numpy builder's own words, so both emit the same ``BvhData``.

The primitives live in one array in their final order from the start: a
node's range [start, start + size) is where its primitives end up, so a
level partitions each range in place (from one buffer into the other) and
a leaf's rows are never touched again; no compaction, no gather. One
work-item per node of the level walks its range sequentially (centroid
bounds, bins, partition): the per-node boxes and counts stay private, so
there are no atomics and nothing depends on the work-group size or on the
order in which work-items run. The levels near the root have few nodes and
so little parallelism; they are also few.

The median fallback (nodes whose centroids coincide, and every node from
``MEDIAN_DEPTH`` on) is rare and runs here, on the host, with
``bvh_sah``'s own ``_halve``.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.constants import SAH_BINS
from ..cl.programs import launch, programs
from . import bvh_sah
from ..cl.layout import BvhNode
from .bvh_tree import BvhData, flatten

# From this many primitives on, build_bvh(queue=...) builds SAH trees here.
# The device build of the bunny (69k triangles) takes a fifth of the numpy
# one's 0.1 s, but a process' first device build also loads the program
# and its kernel (about 0.1 s from a warm PoCL cache, 0.5 s cold: `oclgi
# warm` fills it): at this size a first build breaks even, and every later
# one (other objects, other scenes) gains (bench/HISTORY.md, "BVH build").
DEVICE_MIN_PRIMITIVES = 50_000


def program(ctx: cl.Context):
    return programs(ctx).get("bvh_sah_device")


def build_sah_device(queue: cl.CommandQueue, box_lo: np.ndarray, box_hi: np.ndarray, leaf_size: int = 4,
                     local_size: int | None = None) -> BvhData:
    """``bvh_sah.build_sah(box_lo, box_hi, leaf_size)``, built on ``queue``'s
    device (``local_size``: the work-group size, which changes nothing)."""
    box_lo = np.asarray(box_lo, dtype=np.float32)
    box_hi = np.asarray(box_hi, dtype=np.float32)
    n = len(box_lo)
    if n == 0:
        raise ValueError("cannot build a BVH over no primitives")
    if n <= leaf_size:
        return flatten([np.zeros(1, np.int64)], [np.full(1, n, np.int64)], np.arange(n, dtype=np.int64),
                       box_lo, box_hi)
    if n >= 2**31:
        raise ValueError("the device SAH builder indexes fewer than 2^31 primitives")
    if bvh_sah.BINS > SAH_BINS:
        raise ValueError(f"the device builder bins at most {SAH_BINS} ways (cl/constants.py SAH_BINS)")
    ctx = queue.context
    kernel = program(ctx).sah_split
    rows = np.zeros((n, 8), np.float32)
    rows[:, 0:3], rows[:, 4:7] = box_lo, box_hi
    rows[:, 3] = np.arange(n, dtype=np.int32).view(np.float32)
    mf = cl.mem_flags
    src = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=rows)
    dst = cl.Buffer(ctx, mf.READ_WRITE, rows.nbytes)
    order_buf = cl.Buffer(ctx, mf.READ_WRITE, 4 * n)
    max_nodes = n // (leaf_size + 1) + 1  # every node of a level holds more than leaf_size rows
    nodes_buf = cl.Buffer(ctx, mf.READ_ONLY, 8 * max_nodes)
    bounds_buf = cl.Buffer(ctx, mf.READ_ONLY, 32 * max_nodes)
    out_buf = cl.Buffer(ctx, mf.READ_WRITE, 4 * max_nodes)
    children_buf = cl.Buffer(ctx, mf.READ_WRITE, 128 * max_nodes)

    sizes = np.array([n], np.int64)  # the level's nodes still to split: their sizes,
    starts = np.zeros(1, np.int64)  # and their ranges' starts in the final order
    bounds = _unknown(1)  # and their centroid bounds (lo, hi), as their parents found them
    first, count = [np.ones(1, np.int64)], [np.zeros(1, np.int64)]  # root: inner, children 1 and 2
    boxes = []  # per level after the root: its nodes' boxes (lo, hi; float8 rows)
    next_id, level = 1, 0
    while len(sizes):
        m = len(sizes)
        n_bins = int(min(bvh_sah.BINS, max(4, 1 << int(np.ceil(np.log2(int(sizes.sum()) / m))))))
        if level >= bvh_sah.MEDIAN_DEPTH:
            n_left = np.full(m, -1, np.int64)
            children = np.empty((m, 4, 8), np.float32)
        else:
            cl.enqueue_copy(queue, nodes_buf, np.stack([starts, sizes], axis=1).astype(np.int32))
            cl.enqueue_copy(queue, bounds_buf, bounds)
            launch(queue, kernel, m, src, dst, order_buf, nodes_buf, bounds_buf, m, n_bins, leaf_size, out_buf,
                   children_buf, local_size=local_size)
            out = np.empty(m, np.int32)
            children = np.empty((m, 4, 8), np.float32)
            cl.enqueue_copy(queue, out, out_buf)
            cl.enqueue_copy(queue, children, children_buf)
            n_left = out.astype(np.int64)
        halve = n_left < 0
        if halve.any():
            n_left[halve], children[halve] = _halve_on_host(queue, src, dst, order_buf, starts[halve],
                                                            sizes[halve], leaf_size)

        # The next level: the children of these nodes, left then right (bvh_sah.build_sah).
        child_size = np.stack([n_left, sizes - n_left], axis=1).ravel()
        child_start = np.stack([starts, starts + n_left], axis=1).ravel()
        leaf = child_size <= leaf_size
        next_id += 2 * m
        f = np.where(leaf, child_start, 0)
        f[~leaf] = next_id + 2 * np.arange(int((~leaf).sum()))
        first.append(f)
        count.append(np.where(leaf, child_size, 0))
        boxes.append(children[:, 0::2].reshape(2 * m, 8))
        sizes, starts = child_size[~leaf], child_start[~leaf]
        bounds = np.ascontiguousarray(children[:, 1::2].reshape(2 * m, 8)[~leaf])
        src, dst = dst, src
        level += 1
    order = np.empty(n, np.int32)
    cl.enqueue_copy(queue, order, order_buf)

    box = np.concatenate([np.zeros((1, 8), np.float32)] + boxes)
    box[0, 0:3] = np.minimum(box[1, 0:3], box[2, 0:3])  # the root: its children's union
    box[0, 4:7] = np.maximum(box[1, 4:7], box[2, 4:7])
    nodes = np.zeros(len(box), dtype=BvhNode)
    nodes["lo"], nodes["hi"] = box[:, 0:3] + np.float32(0), box[:, 4:7] + np.float32(0)  # +0: flatten's zeros
    nodes["first"], nodes["count"] = np.concatenate(first), np.concatenate(count)
    return BvhData(nodes=nodes, order=order.astype(np.int64), depth=len(first))


def _unknown(m: int) -> np.ndarray:
    """Centroid bounds that sah_split finds itself (lo > hi)."""
    b = np.empty((m, 8), np.float32)
    b[:, :4], b[:, 4:] = np.inf, -np.inf
    return b


def _halve_on_host(queue, src, dst, order_buf, starts, sizes, leaf_size):
    """Partition the given nodes' ranges of ``src`` into ``dst`` by
    ``bvh_sah._halve`` (the first half along the longest centroid axis, in
    centroid then position order), leaf children's ids into ``order``.
    Returns the left children's sizes and the children's records as
    sah_split writes them (box, then centroid bounds left unknown)."""
    n = _rows(src)
    rows = np.empty((n, 8), np.float32)
    out_rows = np.empty((n, 8), np.float32)
    order = np.empty(n, np.int32)
    cl.enqueue_copy(queue, rows, src)
    cl.enqueue_copy(queue, out_rows, dst)
    cl.enqueue_copy(queue, order, order_buf)
    m = len(sizes)
    seg = np.repeat(np.arange(m), sizes)
    seg_first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    in_seg = np.arange(len(seg)) - seg_first[seg]
    at = starts[seg] + in_seg  # the rows' places in the final order
    r = rows[at]
    cen = (0.5 * (r[:, 0:3].astype(np.float64) + r[:, 4:7])).astype(np.float32).T
    ext = np.maximum.reduceat(cen, seg_first, axis=1) - np.minimum.reduceat(cen, seg_first, axis=1)
    left = bvh_sah._halve(np.zeros(len(seg), bool), np.ones(m, bool), seg, sizes, cen, ext)
    n_left = sizes // 2
    rank_l = np.cumsum(left) - left
    rank_l -= rank_l[seg_first[seg]]
    new_at = starts[seg] + np.where(left, rank_l, n_left[seg] + in_seg - rank_l)
    out_rows[new_at] = r
    child_size = np.where(left, n_left[seg], sizes[seg] - n_left[seg])
    done = child_size <= leaf_size
    order[new_at[done]] = r[done, 3].view(np.int32)
    cl.enqueue_copy(queue, dst, out_rows)
    cl.enqueue_copy(queue, order_buf, order)
    # the children's boxes over their new ranges (left child first)
    child_first = (np.stack([seg_first, seg_first + n_left], axis=1).ravel())
    moved = out_rows[np.sort(new_at)]  # the nodes' ranges after the partition, node by node
    children = np.empty((m, 4, 8), np.float32)
    children[:, 1::2] = _unknown(2 * m).reshape(m, 2, 8)
    children[:, 0::2, 0:4] = np.minimum.reduceat(moved[:, 0:4], child_first, axis=0).reshape(m, 2, 4)
    children[:, 0::2, 4:8] = np.maximum.reduceat(moved[:, 4:8], child_first, axis=0).reshape(m, 2, 4)
    return n_left, children


def _rows(buf: cl.Buffer) -> int:
    return buf.size // 32
