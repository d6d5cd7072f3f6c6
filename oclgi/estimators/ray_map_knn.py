"""Ray Maps' k-nearest-ray mode (Havran, Bittner, Herzog, Seidel 2005, "Ray
maps for global illumination", EGSR; DESIGN.md section 3): irradiance from
the k stored segments nearest to a query point.

Algorithm. Every stored segment (origin o, unit direction w, length t_end,
power Phi) of the run is kept, in (path, bounce) order, the *canonical
order*: a segment's index in it is its id, and it ranks segments as their
global slots ``path * max_depth + bounce`` do, whatever the batch size. At
``resolve`` a BVH is built over the segments' pieces and, for each query
point x with unit normal n, one work-item finds the k nearest segments that
arrive on the front side (``w . n < 0``, as in DETP and Photon Maps) under
the metric, with the bounded private max-heap of the Photon Map search
(kernels/point_index.h), the search radius shrinking as the heap fills
(kernels/ray_map_knn.cl). With r_k the distance to the k-th nearest:

    E(x) = sum_{j<k}  Phi_j / (pi r_k^2)      estimator "k-1" (default)
    E(x) = sum_{j<=k} Phi_j / (pi r_k^2)      estimator "k"

the convention of :mod:`oclgi.estimators.photon_map`: for a locally
uniform density of crossings, pi r_k^2 out to the k-th is Gamma(k)
distributed and the k-1 sum is the unbiased one; the k sum reads high by
k / (k-1).

Metrics (``metric``), t the parameter of the point of the segment that is
measured, d = |o + t w - x|:

    "plane"  (default) the crossing of x's tangent plane, t = (x-o).n / w.n.
             Only segments that cross it within 0 < t <= t_end + e (e the
             extension, as DETP's) are candidates. The crossings' density
             on the plane is the irradiance, so this is DETP's estimate
             with the disc's radius set by the k-th crossing: at a fixed
             radius it selects exactly DETP's segments.
    "ray"    the nearest point of the segment, t clamped to [0, t_end + e].
    "line"   the nearest point of the supporting line (t unbounded).
The "ray" and "line" distances are measured across each ray, not in the
tangent plane: a disc of radius r facing the ray catches a segment of
direction w where the tangent disc would need radius r / |w.n|, so these
estimates weigh light by the solid angle, not by the cosine, and read high
by the ratio of the front hemisphere's fluence to the irradiance (2 for
diffuse light, 1 at normal incidence); "line" also counts segments that end
before reaching x. They are the paper's alternatives and are offered for
comparison; "plane" estimates irradiance.

Ties: neighbours are ranked by (squared float32 distance, id), so equal
distances keep the smaller id (the smaller global slot): the sets do not
depend on the traversal, the work-group size or the batch split. Sums are
64-bit fixed point (each power quantised once, segment_quantise), so
results are bit-reproducible.

Index. The BVH (``build_bvh``, host numpy) is over *pieces*: each segment's
parameter range (plane and ray: [0, t_end + e]; line: the whole line) is
clipped to the box B_M, the box of the query points and the segments'
origins grown by M (its diagonal) on every side, and cut into pieces no
longer than ``piece`` times M (at most 64 per segment and 4 per segment on
average, the length growing when needed, as
:mod:`oclgi.estimators.detp_ray_map`'s: a segment's box is as long as the
segment, and without pieces a segment across the scene is met by every
query under it). A piece claims its own range of t, the end pieces
out to -inf and +inf, so each query's t is claimed by exactly one piece. A
point outside B_M is at least M from every query point, so the traversal's
lower bound of a node is min(box distance, M^2): escaping segments and whole
lines need no box to infinity. Leaves hold at most ``leaf_size`` pieces.
For the plane metric a node whose box misses x's tangent plane holds no
crossing nearer than M, so its bound is M^2.

The search runs in two passes: the first looks only within r0 =
R0_FACTOR (2) times the k-th distance of a uniform density (the run's
segments over the scene's area), so that the search before the heap fills
does not range over every box; a point that finds fewer than k there
searches again without it. No result depends on r0 (a node is skipped only
when its bound exceeds r0^2, which a full heap's k-th d2 does not).

Cost, measured on the Cornell box (10^5 photon paths: 222,288 segments,
3.6 pieces each; k = 50, r_k about 0.05 of the box's 0.55; 2-core AMD
EPYC, pthread-haswell, shared): the build is host work, about 1 s (half
of it the BVH); the search of 128 x 128 camera points takes about 1.9 s
(2.75 s in one pass; Photon Maps' whole resolve: 0.2 s), testing 5,900
pieces and visiting 1,390 nodes per point with leaves of 16 (in one pass,
leaves of 4, 8, 16 and 32: 4,900 / 6,100 / 7,400 / 8,600 pieces, 16 and 32
the fastest; a binned SAH tree tested 10% fewer and took 4 s to build;
uncut segments, ``piece=0``, 57,000). About 770 pieces per point have a
box within r_k that meets the plane. A point that faces into a wall of a
closed room has no candidates and searches the whole map (320,000 piece
tests), as Photon Maps' do; camera and vertex points face the light they
get.

Memory bound. kNN needs every segment of the run at once. On the host a
segment takes 40 bytes while gathering (origin, direction, length, power as
float32); on the device, at the search, its power (16 bytes) and its pieces
(40 bytes each: 9 floats and an id, at most 4 per segment on average) and
their BVH nodes (32 bytes each, about 2 per segment): budgeted at
``BYTES_PER_SEGMENT`` = 256. A run may hold at most ``max_segments(device)``
segments: 3/4 of the device's global memory at 256 bytes each, no piece row
larger than the device's largest allocation, and fewer than 2^31. PoCL
reports 4.3 to 9.3 GiB of global memory on the 2-core machines: 12 to 27
million segments, about 4 to 9 million photon paths of the Cornell box (2.9
stored segments per path). ``first_batch`` refuses a run projected beyond
it, ``accumulate`` a run that gets there; the actual index is checked
against the device's limits before it is uploaded, and the build's host
arrays (``HOST_BYTES_PER_PIECE`` = 320 bytes a piece: float64 chords and
boxes, the BVH builder's codes and order, the packed rows; 170 measured at
the peak on the Cornell box) against the host's available memory before
they are made.

Parameters:

    ============  =========  =====================================================
    k             50         neighbours per point, 1..4096 (2.. for "k-1"); a
                             build define (OCLGI_KNN_K): one program per k
    estimator     "k-1"      "k-1" (unbiased for a uniform density) or "k"
    metric        "plane"    "plane", "ray" or "line" (above)
    leaf_size     16         pieces per BVH leaf, 1..64 (4, 8, 16, 32 measured)
    piece         0.05       longest piece, as a fraction of M (the diagonal
                             of the query points' and origins' box); 0 keeps
                             segments whole
    extension     (engine)   e: plane crossings up to e past a segment's end
                             count (concave surfaces), as in DETP
    count_emitted (engine)   False: skip bounce-0 segments (indirect light only)
    ============  =========  =====================================================

A point with fewer than k candidates in the whole map (or a zero normal: a
camera ray that missed) gets E = 0 and r_k = inf; so does the degenerate
r_k = 0.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyopencl as cl

from .. import budget
from ..accel.boxes import PAD, active_discs
from ..accel.bvh_build import build_bvh
from ..accel.point_index import knn_local_size, query_order
from ..cl.constants import LANES, POINT_BVH_STACK
from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError
from .base import work_counts
from .detp_ray_map import PIECE_BUDGET, clip_segments, cut_pieces, piece_counts
from .photon_map import DEFAULT_K, DEVICE_FRACTION, MAX_K, KnnMap, check_k, point_buffers  # noqa: F401 (MAX_K)

METRICS = ("plane", "ray", "line")  # kernels/ray_map_knn.cl's RMK_PLANE, RMK_RAY, RMK_LINE
MAX_LEAF = 64
ROWS = 9  # float rows of a piece (kernels/ray_map_knn.cl)
BYTES_PER_SEGMENT = 256  # device: power 16 + 4 pieces x 40 + nodes (module docstring)
HOST_BYTES_PER_PIECE = 320  # the build's peak (module docstring)
NODE_BYTES = 32  # oclgi.cl.layout.BvhNode
R0_FACTOR = 2.0  # the search's first radius over the uniform density's k-th distance (first_radius)
M2_SHRINK = 1.0 - 1e-3  # M^2 a little smaller: the bound stays below float32 distances beyond B_M


def max_segments(device) -> int:
    """The most segments a run may hold on ``device`` (module docstring)."""
    by_total = int(DEVICE_FRACTION * device.global_mem_size) // BYTES_PER_SEGMENT
    by_buffer = int(device.max_mem_alloc_size) // (ROWS * 4 * PIECE_BUDGET)
    return min(by_total, by_buffer, 2**31 - 1)


def _fail(message: str):
    raise OclgiError(f"ray_map_knn: {message}")


def check_options(k, estimator, metric, leaf_size, piece):
    check_k(k, estimator, "ray_map_knn")
    if metric not in METRICS:
        _fail(f"metric must be one of {', '.join(map(repr, METRICS))}, got {metric!r}")
    if isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer)) or \
            not 1 <= leaf_size <= MAX_LEAF:
        _fail(f"leaf_size must be an integer in 1..{MAX_LEAF}, got {leaf_size!r}")
    if isinstance(piece, bool) or not isinstance(piece, (int, float, np.integer, np.floating)) or \
            not 0 <= piece < math.inf:
        _fail(f"piece must be a number >= 0 (0: segments are not cut), got {piece!r}")


class SegmentKnnIndex:
    """The k nearest front-side segments of query points, on the device.

    ``org``, ``dirs`` (N, 3), ``tmax`` (N,) = t_end + e and ``powers``
    (N, 3): float32 in canonical order (a segment's row is its id).
    ``bound_lo``/``bound_hi``: a box holding every query point to be
    searched. ``metric`` one of METRICS. Built once, queried any number of
    times (for points in the box).
    """

    def __init__(self, queue, org, dirs, tmax, powers, bound_lo, bound_hi, metric: str = "plane",
                 leaf_size: int = 16, piece: float = 0.05, count_work: bool = False):
        self.queue, self.ctx = queue, queue.context
        self.metric = metric
        self.count_work = bool(count_work)
        org, dirs, tmax = (np.ascontiguousarray(a, np.float32) for a in (org, dirs, tmax))
        n = self.n = len(org)
        if n == 0:
            _fail("no segments to search (no photon was traced)")
        if n >= 2**31:
            _fail(f"{n:,} segments; ids are 32-bit")
        # B_M: the query points' and the origins' box U grown by M = its
        # diagonal. Every segment starts in U, so every one meets B_M.
        u_lo = np.minimum(org.min(axis=0).astype(np.float64), bound_lo)
        u_hi = np.maximum(org.max(axis=0).astype(np.float64), bound_hi)
        scale = float(max(np.abs(u_lo).max(), np.abs(u_hi).max(), 1e-30))
        m = float(max(np.linalg.norm(u_hi - u_lo), 1e-6 * scale, 1e-30))
        self.m2 = np.float32((M2_SHRINK * m) ** 2)
        lo, hi = u_lo - m, u_hi + m
        o64, w64 = org.astype(np.float64), dirs.astype(np.float64)
        if metric == "line":
            t0, t1 = np.full(n, -np.inf), np.full(n, np.inf)
        else:
            t0, t1 = np.zeros(n), tmax.astype(np.float64)
        enter, leave = clip_segments(o64, w64, t1, lo, hi, t0)
        # a zero-length segment (t_end = 0 with no extension) or rounding at B_M's edge
        leave = np.maximum(leave, enter)
        # Pieces, each claiming its own range of t (detp_ray_map.cut_pieces): a partition of the line.
        k = piece_counts(enter, leave, float(piece) * m)
        budget.check(budget.Need(f"the k-nearest map of {n:,} segments", {}, int(k.sum()) * HOST_BYTES_PER_PIECE,
                                 "trace fewer photons or use a DETP method"))
        seg, t_a, t_b, claim_lo, claim_hi = cut_pieces(enter, leave, k)
        # Boxes in float64, padded far beyond float32's rounding of o + t w.
        pad = PAD * max(scale, m)
        p0 = o64[seg] + t_a[:, None].astype(np.float64) * w64[seg]
        p1 = o64[seg] + t_b[:, None].astype(np.float64) * w64[seg]
        box_lo = (np.minimum(p0, p1) - pad).astype(np.float32)
        box_hi = (np.maximum(p0, p1) + pad).astype(np.float32)
        del p0, p1
        bvh = build_bvh(box_lo, box_hi, int(leaf_size))
        del box_lo, box_hi
        if bvh.depth > POINT_BVH_STACK:
            _fail(f"the segment BVH is {bvh.depth} levels deep; the search stack holds {POINT_BVH_STACK}")
        self.pieces = p = len(seg)
        self.stride = p + LANES
        device = queue.device
        row_bytes, node_bytes = self.stride * 4, len(bvh.nodes) * NODE_BYTES
        total = ROWS * row_bytes + node_bytes + n * 16
        if max(ROWS * row_bytes, node_bytes) > device.max_mem_alloc_size or total > device.global_mem_size:
            _fail(f"the map of {n:,} segments ({p:,} pieces) needs {total / 2**20:.0f} MiB of device memory, "
                  f"more than the device allows; trace fewer photons or use a DETP method")
        o = seg[bvh.order]
        soa = np.zeros((ROWS, self.stride), np.float32)  # padding lanes: w = 0, never front side
        soa[0:3, :p] = org[o].T
        soa[3:6, :p] = dirs[o].T
        soa[6, :p] = tmax[o]
        soa[7, :p] = claim_lo[bvh.order]
        soa[8, :p] = claim_hi[bvh.order]
        self.nodes = self._upload(bvh.nodes)
        self.soa = self._upload(soa)
        self.pid = self._upload(np.concatenate([o.astype(np.int32), np.full(LANES, -1, np.int32)]))
        pw = np.zeros((n, 4), np.float32)
        pw[:, :3] = powers
        self.power = self._upload(pw)
        self.work_buf = self._upload(np.zeros(3, np.uint64), cl.mem_flags.READ_WRITE)

    def _upload(self, array, flags=cl.mem_flags.READ_ONLY) -> cl.Buffer:
        return cl.Buffer(self.ctx, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(array))

    def kernel(self, k: int):
        defines = {"knn_k": int(k), **({"count_work": 1} if self.count_work else {})}
        return programs(self.ctx).get("ray_map_knn", **defines).rmk_knn

    def search(self, qpos: cl.Buffer, qnrm: cl.Buffer, order: cl.Buffer, n_points: int, k: int,
               include_kth: bool, acc: cl.Buffer, r2: cl.Buffer, ids: cl.Buffer | None = None,
               d2: cl.Buffer | None = None, local_size: int | None = None, r0: float = math.inf):
        """Run the search: acc (n, 3) int64 sums, r2 (n,) float32; ids/d2 (n, k) when given.
        ``r0``: the first pass's radius (kernels/ray_map_knn.cl); it changes no result."""
        write = ids is not None
        dummy = ids if write else acc
        launch(self.queue, self.kernel(k), n_points, self.nodes, self.soa, self.stride, self.pid, self.power,
               qpos, qnrm, order, n_points, METRICS.index(self.metric), self.m2, np.float32(float(r0) ** 2),
               int(bool(include_kth)),
               acc, r2, int(write), dummy, d2 if write else dummy, self.work_buf,
               local_size=knn_local_size(k, local_size))

    def neighbours(self, positions, normals, k: int, include_kth: bool = False, local_size: int | None = None,
                   r0: float = math.inf):
        """The k nearest front-side segments of each point: (ids, d2, acc,
        r2): ids and d2 (n, k) int32 and float32 in ascending (d2, id)
        order, -1 / inf past the last one found; the sums and radii of the
        estimate. For tests and studies."""
        n = len(positions)
        pos, nrm = np.zeros((n, 4), np.float32), np.zeros((n, 4), np.float32)
        pos[:, :3], nrm[:, :3] = np.asarray(positions)[:, :3], np.asarray(normals)[:, :3]
        bufs = [self._upload(pos), self._upload(nrm), self._upload(query_order(pos))]
        rw = cl.mem_flags.READ_WRITE
        out = [cl.Buffer(self.ctx, rw, max(size, 8)) for size in (n * 24, n * 4, n * k * 4, n * k * 4)]
        self.search(*bufs, n, k, include_kth, *out, local_size=local_size, r0=r0)
        acc, r2, ids, d2 = (read_buffer(self.queue, b, shape, dtype) for b, shape, dtype in zip(
            out, ((n, 3), n, (n, k), (n, k)), (np.int64, np.float32, np.int32, np.float32)))
        return ids, d2, acc, r2

    def work(self) -> dict:
        return work_counts(self.queue, self.work_buf)


STATE_KEYS = ("segment_origins", "segment_directions", "segment_lengths", "segment_powers")


class RayMapKnn(KnnMap):
    """The estimator (module docstring): gathers segments batch by batch,
    searches at ``resolve``; ``segments``, ``neighbours`` and ``radii``
    expose the map for tests and studies."""

    name = "ray_map_knn"
    family = "ray_map_knn"
    # A removed segment changes other points' neighbour sets: no exact add/subtract.
    incremental = False
    what, bytes_each = "segment", BYTES_PER_SEGMENT

    def __init__(self, queue, compiled, points, k: int = DEFAULT_K, estimator: str = "k-1", metric: str = "plane",
                 leaf_size: int = 16, piece: float = 0.05, radius=None, extension: float = 0.0, **kw):
        # radius is DETP's; the k-th neighbour sets the radius here
        super().__init__(queue, compiled, points, **kw)
        check_options(k, estimator, metric, leaf_size, piece)
        self.k, self.estimator, self.metric = int(k), estimator, metric
        self.leaf_size, self.piece = int(leaf_size), float(piece)
        # the user's extension plus DETP's scene-relative tolerance (base.DetpEstimator)
        self.ext = np.float32(float(extension or 0.0) + 10.0 * compiled.eps)
        self.limit = max_segments(queue.device)
        self.k_resolve = programs(self.ctx).get("photon_map").pm_resolve  # E = acc / (scale pi r2)
        self.positions, self.normals, self.order, self.acc, self.r2, self.irr = point_buffers(self, points)
        self.chunks: list[tuple[np.ndarray, ...]] = []
        self.n_segments = 0
        self.knn: SegmentKnnIndex | None = None
        self.build_seconds = 0.0  # host: the pieces and their BVH
        self.query_seconds = 0.0  # device: the search

    # -- gathering ---------------------------------------------------------
    def accumulate(self, batch):
        segs = batch.read_segments(self.queue)
        keep = (segs["dir"] != 0).any(axis=1)  # empty slots and holes have no direction
        if not self.count_emitted:
            keep[::batch.max_depth] = False  # bounce 0: the segments leaving the lights
        s = segs[keep]
        m = len(s)
        self._check_room(self.n_segments + m)
        if m == 0:
            return
        self.chunks.append((np.ascontiguousarray(s["org"]), np.ascontiguousarray(s["dir"]),
                            np.ascontiguousarray(s["t_end"]), np.ascontiguousarray(s["power"])))
        self.n_segments += m
        self.knn = None  # indexes the segments gathered before these

    def first_batch(self, paths_done: int, paths_total: int, segments: int) -> None:
        self._check_projected(self.n_segments, paths_done, paths_total)

    def segments(self):
        """All gathered segments in canonical order: origins, directions
        (N, 3), lengths (N,), powers (N, 3), float32 (powers in units of the
        largest photon power)."""
        z = np.zeros((0, 3), np.float32)
        return self._joined((z, z, np.zeros(0, np.float32), z))

    def state(self) -> dict:
        """The state is the segments (the sums come at the search)."""
        return dict(zip(STATE_KEYS, self.segments()))

    def restore(self, state: dict) -> None:
        self.n_segments, self.knn = self._restore_chunks(state, STATE_KEYS, flat=("segment_lengths",)), None

    # -- the estimate ---------------------------------------------------------
    def build_index(self) -> SegmentKnnIndex:
        if self.knn is None:
            if self.n_segments < self.k:
                _fail(f"only {self.n_segments:,} segments for k = {self.k}; trace more photons or lower k")
            t0 = time.perf_counter()
            org, dirs, t_end, power = self.segments()
            # the box of the points that search (a zero normal, a camera ray's miss, finds nothing)
            pos = self.points.positions[active_discs(self.points), :3]
            if not len(pos):
                pos = org
            self.knn = SegmentKnnIndex(self.queue, org, dirs, t_end + self.ext, power,
                                       pos.min(axis=0).astype(np.float64), pos.max(axis=0).astype(np.float64),
                                       self.metric, self.leaf_size, self.piece, self.count_work)
            self.build_seconds += time.perf_counter() - t0
        return self.knn

    def resolve(self, scale: float) -> cl.Buffer:
        """Irradiance (float4 per point, on the device): E = acc / (scale pi r_k^2)."""
        knn = self.build_index()
        t0 = time.perf_counter()
        knn.search(self.positions, self.normals, self.order, self.n, self.k, self.estimator == "k",
                   self.acc, self.r2, local_size=self.local_size, r0=self.first_radius())
        launch(self.queue, self.k_resolve, self.n, self.acc, self.r2, self.n, 1.0 / (scale * math.pi), self.irr)
        self.queue.finish()
        self.query_seconds += time.perf_counter() - t0
        return self.irr

    def first_radius(self) -> float:
        """The search's first radius: R0_FACTOR times the k-th distance
        where the run's segments end uniformly over the scene's area A,
        sqrt(k A / (pi N)); points that find fewer than k within it search
        again without it (no result depends on it)."""
        area = float(np.sum(self.compiled.areas, dtype=np.float64))
        if not area > 0 or not self.n_segments:
            return math.inf
        return R0_FACTOR * math.sqrt(self.k * area / (math.pi * self.n_segments))

    def replace_points(self, index: np.ndarray, new) -> None:
        """Points ``index`` moved; the map's box holds the old points only, so it is built again."""
        self.move_points(index, new)
        self.order = self.upload(query_order(self.points.positions))
        self.knn = None

    def neighbours(self, k: int | None = None):
        """The k nearest front-side segments of this estimator's points:
        (ids, d2), ids in canonical order (see ``segments``)."""
        k = self.k if k is None else k
        ids, d2, _, _ = self.build_index().neighbours(self.points.positions, self.points.normals, k)
        return ids, d2
