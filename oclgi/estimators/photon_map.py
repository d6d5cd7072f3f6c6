"""Photon Maps (Jensen 1995): irradiance from the k nearest impacts.

Algorithm. Every segment that ends on a surface is an *impact*: position
``org + t_end dir``, arriving direction ``dir``, power ``Phi``. Batches of
traced paths are compacted on the device (``pm_count``/``pm_gather``,
kernels/photon_map.cl) and their impacts gathered on the host in
(path, bounce) order, the *canonical order*: an impact's index in it is its
id, the same whatever the batch size. At ``resolve`` a spatial index is built
over all impacts and, for each query point x with normal n, one work-item
finds the k nearest impacts that arrive on the front side (``dir . n < 0``,
as in DETP) with a bounded max-heap in private memory (kernels/
photon_map.h). With r_k the distance to the k-th nearest:

    E(x) = sum_{j<k}  Phi_j / (pi r_k^2)      estimator "k-1" (default)
    E(x) = sum_{j<=k} Phi_j / (pi r_k^2)      estimator "k"

Why k-1 is the default: for impacts of locally uniform density lambda
(a Poisson process on the surface), the area pi r_k^2 out to the k-th
nearest is Gamma(k, 1/lambda) distributed and E[1 / Gamma(k, 1)] = 1/(k-1),
so (k-1) Phi / (pi r_k^2) is unbiased for lambda Phi while k Phi / (pi r_k^2)
over-estimates by exactly k / (k-1) (DESIGN.md section 3); the relative
standard deviation of the k-1 estimate is 1 / sqrt(k-2). Both estimates share
r_k, so their ratio at a point is exactly sum_k / sum_{k-1}. (The other
biases, boundary, proximity and topological, are the method's.)

Ties: neighbours are ranked by (squared float32 distance, id), so equal
distances keep the smaller id; the set is reproducible and equals a brute
force over the same floats. Sums are 64-bit fixed point (each power
quantised once, like every estimator), so results are bit-reproducible
across work-group sizes, batch splits and index types.

Index. Two were measured (k = 50, 10^6 impacts, 10^5 queries, front
side on; throughput against scipy's cKDTree(workers=2) in the same run, on
the 2-core machines): a BVH over the impacts, and a hashed uniform grid
searched shell by shell around the query's cell, its cells sized for a
mean of 16 impacts per occupied cell (8, 16 and 32 tried).

    data (queries)                           BVH, leaf 16   grid    cKDTree
    Cornell box (camera points, 317^2)       2.1x           1.8x    0.29 Mq/s
    point light on a plane (uniform on it)   2.2x           2.6x    0.26 Mq/s
    uniform cube (random directions)         1.5x           1.7x    0.18 Mq/s
    caustic (half the impacts in a disc      2.0x           0.4x    0.26 Mq/s
      1/100 of the unit square wide)

The BVH is the default: close to the grid where the density is even, and
it keeps its speed where the density is not (in the caustic the grid's
cells held thousands of impacts: 12,339 tested per query, against 135). It
builds faster too (0.33 s against 0.5 s for 10^6 impacts). It is a
Karras-style LBVH on 63-bit Morton codes with cubic cells (_point_bvh: the
shared 30-bit builder and per-axis scaling cost 7x and 2x more tests on the
caustic and the plane); queries run in Morton order (2-4x faster than
random order on random queries).

Cost: a point whose front side sees few impacts nearby searches far (on
the Cornell box, surface points facing into the walls tested 7,300 impacts
each instead of 110); camera and vertex points face the light they get.

Memory bound. kNN needs every impact at once: 44 bytes each on the device
(position and direction as 6 floats, id, power as float4) plus the BVH
(budgeted at 20 bytes), and 36 on the host while gathering (plus about
as much again while the index is built). A run may hold at most
``max_impacts(device)`` impacts: 3/4 of the device's global memory at 64
bytes per impact, no buffer larger than the device's largest allocation
(24 bytes x impacts), and fewer than 2^31. PoCL reports part of the host's
free memory as global memory (4.3 to 9.3 GiB seen on the 2-core machines),
so the bound is 54 to 117 million impacts there; the Cornell box makes 1.9
impacts per photon path, so some 28 million photons at least. Beyond it
``accumulate`` raises OclgiError: use fewer photons, or DETP, which
streams segments.

Parameters:

    ============  =========  =====================================================
    k             50         neighbours per point, 1..4096 (2.. for "k-1"); a
                             build define (OCLGI_KNN_K): one program per k
    estimator     "k-1"      "k-1" (unbiased for a uniform density) or "k"
    index         "bvh"      "bvh" (default) or "grid" (the measured alternative)
    front_only    True       count only impacts arriving on the normal's side
    leaf_size     16         impacts per BVH leaf (8, 16, 32 measured: 16)
    count_emitted (engine)   False: skip bounce-0 impacts (indirect light only)
    ============  =========  =====================================================

A point with fewer than k front-side impacts in the whole map (or a zero
normal: a camera ray that missed) gets E = 0 and r_k = inf; so does the
degenerate r_k = 0 (k impacts at the very point).
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from ..accel.bvh_build import build_from_codes
from ..cl.programs import launch, programs
from ..errors import OclgiError
from .base import Estimator

MAX_K = 4096  # the private heap takes 8 bytes per neighbour and work-item
# PoCL keeps a work-group's private arrays on a thread's stack (8 MiB): k =
# 2048 crashed at 1024 work-items per group. The search caps its group so
# that heaps and stacks stay within this budget (results do not depend on it).
PRIVATE_BUDGET = 2 << 20
ESTIMATOR_KINDS = ("k-1", "k")
INDEX_KINDS = ("bvh", "grid")
BYTES_PER_IMPACT = 64  # 44 on the device (6 floats, id, float4 power) + the BVH's share
DEVICE_FRACTION = 0.75  # of global memory for the impacts; the rest: batch, scene, points
LANES = 8  # impacts tested at once (PM_LANES)
STACK_SIZE = 96  # PM_STACK_SIZE (photon_map.h): levels of the impact BVH
DEFAULT_LOCAL = 64  # work-group size of the search when the engine sets none (measured)
GRID_KEY_BITS = 21  # cells per axis < 2^21 (three packed in a 64-bit key)
EMPTY = np.uint64(0xFFFFFFFFFFFFFFFF)
HASH_MUL = np.uint64(0x9E3779B97F4A7C15)


def max_impacts(device) -> int:
    """The most impacts a Photon Map run may hold on ``device`` (module docstring)."""
    by_total = int(DEVICE_FRACTION * device.global_mem_size) // BYTES_PER_IMPACT
    by_buffer = int(device.max_mem_alloc_size) // 24  # the 6 position/direction rows
    return min(by_total, by_buffer, 2**31 - 1)


DEFAULT_K = 50  # neighbours per estimate


def _check_k(k, estimator):
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= MAX_K:
        raise OclgiError(f"photon_map: k must be an integer in 1..{MAX_K}, got {k!r}")
    if estimator not in ESTIMATOR_KINDS:
        raise OclgiError(f"photon_map: estimator must be one of {', '.join(map(repr, ESTIMATOR_KINDS))}, "
                         f"got {estimator!r}")
    if estimator == "k-1" and k < 2:
        raise OclgiError("photon_map: the 'k-1' estimator needs k >= 2")


def _check_index(index, leaf_size):
    if index not in INDEX_KINDS:
        raise OclgiError(f"photon_map: index must be one of {', '.join(map(repr, INDEX_KINDS))}, "
                         f"got {index!r}")
    if isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer)) or not 1 <= leaf_size <= 64:
        raise OclgiError(f"photon_map: leaf_size must be an integer in 1..64, got {leaf_size!r}")


def _float4(xyz) -> np.ndarray:
    out = np.zeros((len(xyz), 4), np.float32)
    out[:, :3] = np.asarray(xyz)[:, :3]
    return out


def _grid_cell_size(pos: np.ndarray, target: float) -> float:
    """Cell size whose occupied cells hold about ``target`` impacts each.

    Occupancy grows like h^D (D = 2 on surfaces, 3 in volumes): measure it at
    two sizes, fit D, solve, and correct once more at the solution.
    """
    lo, hi = pos.min(axis=0).astype(np.float64), pos.max(axis=0).astype(np.float64)
    extent = max(float((hi - lo).max()), 1e-30)

    def occupancy(h):
        c = np.floor((pos - lo) / h).astype(np.int64)
        key = c[:, 0] | (c[:, 1] << 21) | (c[:, 2] << 42)
        return len(pos) / len(np.unique(key))

    h1, h2 = extent / 32, extent / 64
    o1, o2 = occupancy(h1), occupancy(h2)
    d = float(np.clip(math.log2(o1 / o2) if o2 > 0 and o1 > o2 else 3.0, 1.0, 3.0))
    h = h2 * (target / o2) ** (1.0 / d)
    h = h * (target / occupancy(h)) ** (1.0 / d)
    # keys hold 21 bits per axis
    return float(max(h, extent / (2**GRID_KEY_BITS - 2), 1e-30))


class KnnIndex:
    """k nearest front-side impacts of query points, on the device.

    ``positions``, ``directions``, ``powers``: (N, 3) float32 in canonical
    order (an impact's row is its id). ``index``: "bvh" or "grid";
    ``leaf_size`` (BVH) or ``grid_occupancy`` (impacts per occupied cell)
    tune them. Built once, queried any number of times.
    """

    def __init__(self, queue, positions, directions=None, powers=None, index: str = "bvh",
                 leaf_size: int = 16, grid_occupancy: float = 16.0, count_work: bool = False):
        _check_index(index, leaf_size)
        self.queue = queue
        self.ctx = queue.context
        self.index = index
        self.count_work = bool(count_work)
        pos = np.ascontiguousarray(positions, np.float32)
        self.n = len(pos)
        if self.n == 0:
            raise OclgiError("photon_map: no impacts to search (no photon hit a surface)")
        if self.n >= 2**31:
            raise OclgiError(f"photon_map: {self.n:,} impacts; ids are 32-bit")
        dirs = np.zeros_like(pos) if directions is None else np.ascontiguousarray(directions, np.float32)
        pw = np.zeros_like(pos) if powers is None else np.ascontiguousarray(powers, np.float32)
        if index == "bvh":
            nodes, order, depth = _point_bvh(pos, int(leaf_size))
            if depth > STACK_SIZE:
                raise OclgiError(f"photon_map: the impact BVH is {depth} levels deep; the search "
                                 f"stack holds {STACK_SIZE}")
            self.nodes = self._upload(nodes)
        else:
            h = _grid_cell_size(pos, float(grid_occupancy))
            lo = pos.min(axis=0).astype(np.float64)
            c = np.floor((pos - lo) / h).astype(np.int64)
            dims = c.max(axis=0) + 1
            keys = (c[:, 0] | (c[:, 1] << 21) | (c[:, 2] << 42)).astype(np.uint64)
            order = np.argsort(keys, kind="stable")  # canonical order within a cell
            ukeys, starts, counts = np.unique(keys[order], return_index=True, return_counts=True)
            bits = max(1, int(math.ceil(math.log2(2 * len(ukeys)))))
            tkeys, tcells = _hash_table(ukeys, starts, counts, bits)
            self.grid = dict(h=h, origin=lo, dims=dims, bits=bits, cells=len(ukeys))
            self.keys = self._upload(tkeys)
            self.cells = self._upload(tcells)
            # A cell's box computed in float32 on the device may miss its
            # impacts by a few ulps of the coordinates: pad every distance.
            mag = float(np.abs(lo).max() + (dims.max() + 1) * h)
            self.slack = np.float32(1e-5 * mag + 1e-4 * h)
        self.order = order
        # structure of arrays in index order, padded by LANES (photon_map.h)
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
        prog = programs(self.ctx).get("photon_map", **defines)
        return prog.pm_knn_bvh if self.index == "bvh" else prog.pm_knn_grid

    def search(self, qpos: cl.Buffer, qnrm: cl.Buffer, order: cl.Buffer, n_points: int, k: int,
               front_only: bool, include_kth: bool, scale: float, acc: cl.Buffer, r2: cl.Buffer,
               ids: cl.Buffer | None = None, d2: cl.Buffer | None = None, local_size: int | None = None):
        """Run the search: acc (n, 3) int64 sums, r2 (n,) float32; ids/d2 (n, k) when given."""
        write = ids is not None
        dummy = ids if write else acc
        common = (self.soa, np.int32(self.stride), self.ids, self.ipower, qpos, qnrm, order, np.int32(n_points),
                  np.int32(bool(front_only)), np.int32(bool(include_kth)), np.float32(scale), acc, r2,
                  np.int32(write), dummy, d2 if write else dummy, self.work_buf)
        if self.index == "bvh":
            args = (self.nodes, *common)
        else:
            g = self.grid
            args = (self.keys, self.cells, np.int32(g["bits"]),
                    np.array([*g["origin"], g["h"]], np.float32),
                    np.array([*g["dims"], 0], np.int32), self.slack, *common)
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
        self.search(*bufs, n, k, front_only, True, 1.0, acc, r2, ids, d2)
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
    cap = max(1, PRIVATE_BUDGET // (8 * int(k) + 8 * STACK_SIZE))
    return int(min(requested or DEFAULT_LOCAL, cap))


def _hash_table(ukeys, starts, counts, bits):
    """Open addressing with linear probing, filled in rounds: each round
    every pending key claims its probe slot, the lowest key (they are sorted)
    wins each free slot, the rest probe on. Deterministic."""
    size = 1 << bits
    mask = np.uint64(size - 1)
    tkeys = np.full(size, EMPTY, np.uint64)
    tcells = np.zeros((size, 2), np.int32)
    with np.errstate(over="ignore"):
        slot = (ukeys * HASH_MUL) >> np.uint64(64 - bits)
    pending = np.arange(len(ukeys))
    while len(pending):
        s = slot[pending]
        free = tkeys[s] == EMPTY
        cand = pending[free]
        won_slots, first = np.unique(s[free], return_index=True)
        winners = cand[first]
        tkeys[won_slots] = ukeys[winners]
        tcells[won_slots, 0] = starts[winners]
        tcells[won_slots, 1] = counts[winners]
        won = np.zeros(len(ukeys), bool)
        won[winners] = True
        pending = pending[~won[pending]]
        slot[pending] = (slot[pending] + np.uint64(1)) & mask
    return tkeys, tcells


def query_order(positions: np.ndarray) -> np.ndarray:
    """Morton order of the query points: neighbouring work-items then search
    neighbouring parts of the index (it changes no result, only the cache
    behaviour)."""
    if len(positions) == 0:
        return np.zeros(1, np.int32)
    return np.argsort(morton63(positions), kind="stable").astype(np.int32)


class PhotonMap(Estimator):
    """The estimator (module docstring): gathers impacts batch by batch,
    searches at ``resolve``; ``impacts``, ``neighbours`` and ``radii``
    expose the map for tests and studies."""

    name = "photon_map"
    # Exact add/subtract does not apply to k nearest neighbours (a removed
    # impact changes other points' neighbour sets); see DESIGN.md section 4.
    incremental = False

    def __init__(self, queue, compiled, points, k: int = DEFAULT_K, estimator: str = "k-1", index: str = "bvh",
                 front_only: bool = True, leaf_size: int = 16, radius=None, extension=None, **kw):
        # radius and extension are DETP parameters; the k-th neighbour sets the radius here
        super().__init__(queue, compiled, points, **kw)
        _check_k(k, estimator)
        _check_index(index, leaf_size)
        if not isinstance(front_only, (bool, np.bool_)):
            raise OclgiError(f"photon_map: front_only must be true or false, got {front_only!r}")
        self.k = int(k)
        self.estimator = estimator
        self.index = index
        self.front_only = bool(front_only)
        self.leaf_size = leaf_size
        self.limit = max_impacts(queue.device)
        prog = programs(self.ctx).get("photon_map")  # compaction and resolve do not depend on k
        self.k_count, self.k_gather, self.k_resolve = prog.pm_count, prog.pm_gather, prog.pm_resolve
        self.positions = self.upload(points.positions)
        self.normals = self.upload(points.normals)
        self.order = self.upload(query_order(points.positions))
        self.acc = self.zeros(self.n * 3 * 8)
        self.r2 = self.zeros(self.n * 4)
        self.irr = self.zeros(self.n * 16)
        self.chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.n_impacts = 0
        self.knn: KnnIndex | None = None

    # -- gathering ---------------------------------------------------------
    def accumulate(self, batch, scale: float):
        n_paths = batch.n_paths
        counts_buf = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, n_paths * 4)
        args = (batch.segments, np.int32(n_paths), np.int32(batch.max_depth), np.int32(self.count_emitted))
        launch(self.queue, self.k_count, n_paths, *args, counts_buf, local_size=self.local_size)
        counts = np.empty(n_paths, np.int32)
        cl.enqueue_copy(self.queue, counts, counts_buf)
        offsets = np.zeros(n_paths, np.int64)
        np.cumsum(counts[:-1], out=offsets[1:])
        m = int(offsets[-1] + counts[-1])
        if self.n_impacts + m > self.limit:
            raise OclgiError(
                f"photon_map: more than {self.limit:,} impacts ({self.n_impacts + m:,} so far); the "
                f"k-nearest search keeps them all in device memory ({BYTES_PER_IMPACT} bytes each, "
                f"{DEVICE_FRACTION:.0%} of {self.queue.device.global_mem_size / 2**30:.1f} GiB); "
                f"trace fewer photons or use method 'detp'")
        if m == 0:
            return
        mf = cl.mem_flags
        off_buf = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=offsets.astype(np.int32))
        bufs = [cl.Buffer(self.ctx, mf.WRITE_ONLY, m * 12) for _ in range(3)]
        launch(self.queue, self.k_gather, n_paths, *args, off_buf, *bufs, local_size=self.local_size)
        host = [np.empty((m, 3), np.float32) for _ in range(3)]
        for h, b in zip(host, bufs):
            cl.enqueue_copy(self.queue, h, b)
        self.chunks.append(tuple(host))
        self.n_impacts += m

    def clear_impacts(self):
        """Forget the gathered impacts and their index (a session gathers its
        store again after a move); the sums and radii stay."""
        self.chunks, self.n_impacts, self.knn = [], 0, None

    def impacts(self):
        """All impacts in canonical order: positions, directions, powers, (N, 3) float32."""
        if not self.chunks:
            z = np.zeros((0, 3), np.float32)
            return z, z, z
        if len(self.chunks) > 1:  # concatenate once, keep one chunk
            self.chunks = [tuple(np.concatenate(c) for c in zip(*self.chunks))]
        return self.chunks[0]

    # -- the estimate ---------------------------------------------------------
    def build_index(self) -> KnnIndex:
        if self.knn is None:
            if self.n_impacts < self.k:
                raise OclgiError(f"photon_map: only {self.n_impacts:,} impacts for k = {self.k}; "
                                 f"trace more photons or lower k")
            pos, dirs, pw = self.impacts()
            self.knn = KnnIndex(self.queue, pos, dirs, pw, index=self.index, leaf_size=self.leaf_size,
                                count_work=self.count_work)
        return self.knn

    def search(self, scale: float, ids: np.ndarray | None = None):
        """The k-nearest search for every point, or for points ``ids`` only
        (their sums and radii are overwritten, the others keep theirs)."""
        knn = self.build_index()
        order, n = self.order, self.n
        if ids is not None:
            if len(ids) == 0:
                return
            ids = np.asarray(ids, np.int32)  # searched in Morton order, for locality only
            order, n = self.upload(ids[query_order(self.points.positions[ids])]), len(ids)
        knn.search(self.positions, self.normals, order, n, self.k, self.front_only,
                   self.estimator == "k", scale, self.acc, self.r2, local_size=self.local_size)

    def irradiance_buffer(self, scale: float) -> cl.Buffer:
        """E = acc / (scale pi r_k^2) from the current sums and radii (float4 per point, on the device)."""
        launch(self.queue, self.k_resolve, self.n, self.acc, self.r2, np.int32(self.n),
               np.float32(1.0 / (scale * math.pi)), self.irr)
        return self.irr

    def resolve(self, scale: float) -> cl.Buffer:
        """Irradiance (float4 per point, on the device): E = acc / (scale pi r_k^2)."""
        self.search(scale)
        return self.irradiance_buffer(scale)

    def replace_points(self, index: np.ndarray, new) -> None:
        """Points ``index`` moved (points on a moved object); the caller searches them again.
        The Morton order of the full search is kept: it only serves locality."""
        self.points.positions[index] = new.positions
        self.points.normals[index] = new.normals
        self.points.barys[index] = new.barys
        cl.enqueue_copy(self.queue, self.positions, self.points.positions)
        cl.enqueue_copy(self.queue, self.normals, self.points.normals)

    def accumulators(self) -> np.ndarray:
        out = np.empty((self.n, 3), np.int64)
        cl.enqueue_copy(self.queue, out, self.acc)
        return out

    def radii(self) -> np.ndarray:
        """r_k per point (inf where fewer than k impacts were found), after resolve."""
        r2 = np.empty(self.n, np.float32)
        cl.enqueue_copy(self.queue, r2, self.r2)
        return np.sqrt(r2)

    def neighbours(self, k: int | None = None):
        """The k nearest front-side impacts of this estimator's points (ids
        in canonical order, see ``impacts``), as KnnIndex.neighbours."""
        k = self.k if k is None else k
        return self.build_index().neighbours(self.points.positions[:, :3], self.points.normals[:, :3], k,
                                             self.front_only)

    def work(self) -> dict | None:
        """Work of the search (u: impact distance tests, nodes: BVH nodes or grid cells visited)."""
        if not self.count_work or self.knn is None:
            return super().work()
        return self.knn.work()
