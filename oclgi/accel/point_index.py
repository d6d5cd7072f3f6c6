"""The k nearest front-side impacts of query points, on the device
(kernels/point_index.cl): a BVH over the impacts on 63-bit Morton codes. The
search of the Photon Map estimator and of its session;
``KnnIndex.neighbours`` serves tests and studies.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.constants import LANES, POINT_BVH_STACK
from ..cl.programs import launch, programs
from ..errors import OclgiError
from .bvh_build import build_from_codes

DEFAULT_LOCAL = 64  # work-group size of the search when the engine sets none (measured)
# PoCL keeps a work-group's private arrays on a thread's stack (8 MiB): k =
# 2048 crashed at 1024 work-items per group. The search caps its group so
# that heaps and stacks stay within this budget (results do not depend on it).
PRIVATE_BUDGET = 2 << 20


def check_leaf_size(leaf_size):
    if isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer)) or not 1 <= leaf_size <= 64:
        raise OclgiError(f"photon_map: leaf_size must be an integer in 1..64, got {leaf_size!r}")


def _float4(xyz) -> np.ndarray:
    out = np.zeros((len(xyz), 4), np.float32)
    out[:, :3] = np.asarray(xyz)[:, :3]
    return out


class KnnIndex:
    """k nearest front-side impacts of query points, on the device.

    ``positions``, ``directions``, ``powers``: (N, 3) float32 in canonical
    order (an impact's row is its id); ``leaf_size``: impacts per BVH leaf.
    Built once, queried any number of times.
    """

    def __init__(self, queue, positions, directions=None, powers=None, leaf_size: int = 16,
                 count_work: bool = False):
        check_leaf_size(leaf_size)
        self.queue = queue
        self.ctx = queue.context
        self.count_work = bool(count_work)
        pos = np.ascontiguousarray(positions, np.float32)
        self.n = len(pos)
        if self.n == 0:
            raise OclgiError("photon_map: no impacts to search (no photon hit a surface)")
        if self.n >= 2**31:
            raise OclgiError(f"photon_map: {self.n:,} impacts; ids are 32-bit")
        dirs = np.zeros_like(pos) if directions is None else np.ascontiguousarray(directions, np.float32)
        pw = np.zeros_like(pos) if powers is None else np.ascontiguousarray(powers, np.float32)
        nodes, order, depth = _point_bvh(pos, int(leaf_size))
        if depth > POINT_BVH_STACK:
            raise OclgiError(f"photon_map: the impact BVH is {depth} levels deep; the search "
                             f"stack holds {POINT_BVH_STACK}")
        self.nodes = self._upload(nodes)
        self.order = order
        # structure of arrays in index order, padded by LANES (point_index.h)
        self.stride = self.n + LANES
        soa = np.zeros((6, self.stride), np.float32)
        soa[0:3, :self.n] = pos[order].T
        soa[3:6, :self.n] = dirs[order].T
        self.soa = self._upload(soa)
        self.ids = self._upload(np.concatenate([order.astype(np.int32), np.full(LANES, -1, np.int32)]))
        self.ipower = self._upload(_float4(pw))
        self.work_buf = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, 3 * 8)
        cl.enqueue_fill_buffer(queue, self.work_buf, np.uint64(0), 0, 3 * 8)

    def _upload(self, array) -> cl.Buffer:
        array = np.ascontiguousarray(array)
        return cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)

    def kernel(self, k: int):
        defines = {"knn_k": int(k)}
        if self.count_work:
            defines["count_work"] = 1
        prog = programs(self.ctx).get("point_index", **defines)
        return prog.pm_knn_bvh

    def search(self, qpos: cl.Buffer, qnrm: cl.Buffer, order: cl.Buffer, n_points: int, k: int,
               front_only: bool, include_kth: bool, acc: cl.Buffer, r2: cl.Buffer,
               ids: cl.Buffer | None = None, d2: cl.Buffer | None = None, local_size: int | None = None):
        """Run the search: acc (n, 3) int64 sums, r2 (n,) float32; ids/d2 (n, k) when given."""
        write = ids is not None
        dummy = ids if write else acc
        args = (self.nodes, self.soa, self.stride, self.ids, self.ipower, qpos, qnrm, order, n_points,
                int(bool(front_only)), int(bool(include_kth)), acc, r2,
                int(write), dummy, d2 if write else dummy, self.work_buf)
        launch(self.queue, self.kernel(k), n_points, *args, local_size=knn_local_size(k, local_size))

    def neighbours(self, positions, normals, k: int, front_only: bool = True):
        """The k nearest front-side impacts of each point: (ids, d2), (n, k)
        int32 and float32 in ascending (d2, id) order; -1 / inf past the
        last one found. For tests and studies."""
        pos = _float4(np.asarray(positions, np.float32))
        nrm = _float4(np.asarray(normals, np.float32))
        n = len(pos)
        bufs = [self._upload(pos), self._upload(nrm), self._upload(query_order(pos))]
        acc = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, max(n * 24, 8))
        r2 = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, max(n * 4, 4))
        ids = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, max(n * k * 4, 4))
        d2 = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, max(n * k * 4, 4))
        self.search(*bufs, n, k, front_only, True, acc, r2, ids, d2)
        out_ids = np.empty((n, k), np.int32)
        out_d2 = np.empty((n, k), np.float32)
        cl.enqueue_copy(self.queue, out_ids, ids)
        cl.enqueue_copy(self.queue, out_d2, d2)
        return out_ids, out_d2

    def work(self) -> dict:
        out = np.empty(3, np.uint64)
        cl.enqueue_copy(self.queue, out, self.work_buf)
        return {"t": int(out[0]), "u": int(out[1]), "nodes": int(out[2])}


def _spread7_table() -> np.ndarray:
    """Bit i of a 7-bit value moved to bit 3 i (the Morton spread), tabulated."""
    v = np.arange(128, dtype=np.uint64)
    out = np.zeros(128, np.uint64)
    for i in range(7):
        out |= ((v >> np.uint64(i)) & np.uint64(1)) << np.uint64(3 * i)
    return out


_SPREAD7 = _spread7_table()


def morton63(points: np.ndarray) -> np.ndarray:
    """63-bit Morton codes of points over their bounding box (21 bits per axis)."""
    p = np.ascontiguousarray(np.asarray(points, np.float32)[:, :3].T)  # rows reduce fast
    lo, hi = p.min(axis=1), p.max(axis=1)
    # Cubic cells (one scale for all axes): impacts on a plane have a flat
    # box whose thin axis holds only rounding noise, which per-axis scaling
    # would spread over a third of the bits (measured: 2x the nodes visited).
    # float32 is enough: the codes only need to be deterministic and local.
    s = np.float32((2**21 - 1) / max(float((hi.astype(np.float64) - lo).max()), 1e-30))
    q = np.minimum(((p - lo[:, None]) * s).astype(np.int32), 2**21 - 1)
    code = np.zeros(p.shape[1], np.uint64)
    for axis in range(3):
        for chunk in range(3):  # 7 bits at a time through the table
            bits = _SPREAD7[(q[axis] >> (7 * chunk)) & 127]
            code |= bits << np.uint64(21 * chunk + 2 - axis)
    return code


def _point_bvh(pos: np.ndarray, leaf_size: int):
    """LBVH over points (oclgi/accel/bvh_build.py) on 63-bit Morton codes.

    Why not the builder's own 30-bit codes: they cannot order impacts finer
    than 1/1024 of the scene, and a caustic packs thousands of impacts into
    one such cell, whose leaves then split by count into boxes as large as
    the cell (measured: 767 impacts tested per k = 50 query on a caustic,
    against 60 here). 63 bits resolve 2^-21 of the scene.
    Returns (nodes, order, depth): leaves index the points in ``order``.
    """
    pos = np.asarray(pos, np.float32)
    bvh = build_from_codes(morton63(pos), pos, pos, leaf_size)
    return bvh.nodes, bvh.order, bvh.depth


def knn_local_size(k: int, requested: int | None = None) -> int:
    """Work-group size of the search: the requested one (or DEFAULT_LOCAL)
    capped so that the group's private heaps fit PRIVATE_BUDGET."""
    cap = max(1, PRIVATE_BUDGET // (8 * int(k) + 8 * POINT_BVH_STACK))
    return int(min(requested or DEFAULT_LOCAL, cap))


def query_order(positions: np.ndarray) -> np.ndarray:
    """Morton order of the query points: neighbouring work-items then search
    neighbouring parts of the index (it changes no result, only the cache
    behaviour)."""
    if len(positions) == 0:
        return np.zeros(1, np.int32)
    return np.argsort(morton63(positions), kind="stable").astype(np.int32)
