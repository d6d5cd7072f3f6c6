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
across work-group sizes and batch splits.

Index: a BVH over the impacts. Measured (k = 50, 10^6 impacts, 10^5
queries, front side on; throughput against scipy's cKDTree(workers=2) in
the same run, on the 2-core machines) against a hashed uniform grid
searched shell by shell around the query's cell, its cells sized for a
mean of 16 impacts per occupied cell (8, 16 and 32 tried; the grid has
since been removed):

    data (queries)                           BVH, leaf 16   grid    cKDTree
    Cornell box (camera points, 317^2)       2.1x           1.8x    0.29 Mq/s
    point light on a plane (uniform on it)   2.2x           2.6x    0.26 Mq/s
    uniform cube (random directions)         1.5x           1.7x    0.18 Mq/s
    caustic (half the impacts in a disc      2.0x           0.4x    0.26 Mq/s
      1/100 of the unit square wide)

The BVH won: close to the grid where the density is even, and it keeps
its speed where the density is not (in the caustic the grid's cells held
thousands of impacts: 12,339 tested per query, against 135). It builds
faster too (0.33 s against 0.5 s for 10^6 impacts). It is a
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

from ..accel.point_index import KnnIndex, check_leaf_size, query_order
from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError
from .base import Estimator

MAX_K = 4096  # the private heap takes 8 bytes per neighbour and work-item
ESTIMATOR_KINDS = ("k-1", "k")
BYTES_PER_IMPACT = 64  # 44 on the device (6 floats, id, float4 power) + the BVH's share
DEVICE_FRACTION = 0.75  # of global memory for the impacts; the rest: batch, scene, points


def max_impacts(device) -> int:
    """The most impacts a Photon Map run may hold on ``device`` (module docstring)."""
    by_total = int(DEVICE_FRACTION * device.global_mem_size) // BYTES_PER_IMPACT
    by_buffer = int(device.max_mem_alloc_size) // 24  # the 6 position/direction rows
    return min(by_total, by_buffer, 2**31 - 1)


DEFAULT_K = 50  # neighbours per estimate
IMPACT_KEYS = ("impact_positions", "impact_directions", "impact_powers")  # a run state's


def point_buffers(est, points) -> tuple:
    """The device buffers of a k-nearest estimate over ``points`` (Photon
    Maps' and ray_map_knn's): positions, normals, their Morton order (the
    search's, for locality only), and what pm_resolve reads and writes per
    point: the int64 RGB sums, r_k^2 and E (float4)."""
    return (est.upload(points.positions), est.upload(points.normals), est.upload(query_order(points.positions)),
            est.zeros(est.n * 3 * 8), est.zeros(est.n * 4), est.zeros(est.n * 16))


def check_k(k, estimator, name: str = "photon_map"):
    """k and the estimator kind of a k-nearest estimate (Photon Maps' and ray_map_knn's)."""
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= MAX_K:
        raise OclgiError(f"{name}: k must be an integer in 1..{MAX_K}, got {k!r}")
    if estimator not in ESTIMATOR_KINDS:
        raise OclgiError(f"{name}: estimator must be one of {', '.join(map(repr, ESTIMATOR_KINDS))}, "
                         f"got {estimator!r}")
    if estimator == "k-1" and k < 2:
        raise OclgiError(f"{name}: the 'k-1' estimator needs k >= 2")


class KnnMap(Estimator):
    """What the k-nearest estimates (Photon Maps, ray_map_knn) share: the
    map's arrays gathered batch by batch in ``chunks`` (canonical order), at
    most ``limit`` of them (``what``: impacts or segments, ``bytes_each`` on
    the device), and the search's radii and work."""

    what = "impact"
    bytes_each = BYTES_PER_IMPACT

    def _check_room(self, count: int) -> None:
        if count > self.limit:
            raise OclgiError(
                f"{self.name}: more than {self.limit:,} {self.what}s ({count:,} so far); the "
                f"k-nearest search keeps them all in device memory ({self.bytes_each} bytes each, "
                f"{DEVICE_FRACTION:.0%} of {self.queue.device.global_mem_size / 2**30:.1f} GiB); "
                f"trace fewer photons or use method 'detp'")

    def _check_projected(self, count: int, paths_done: int, paths_total: int) -> None:
        """The map grows with the photons: a run projected (from its first
        batch) to hold more than ``limit`` stops at its start."""
        if paths_done <= 0 or paths_done >= paths_total:
            return
        projected = count / paths_done * paths_total
        if projected > self.limit:
            raise OclgiError(
                f"{self.name}: {paths_total:,} photons would make about {projected:,.0f} {self.what}s (from the "
                f"first {paths_done:,}), more than the {self.limit:,} this device holds for the k-nearest search "
                f"({self.bytes_each} bytes each); trace fewer photons or use a DETP method, whose memory does not "
                "grow with the photon count")

    def _joined(self, empty: tuple) -> tuple:
        """All gathered arrays in canonical order (``empty`` when none)."""
        if not self.chunks:
            return empty
        if len(self.chunks) > 1:  # concatenate once, keep one chunk
            self.chunks = [tuple(np.concatenate(c) for c in zip(*self.chunks))]
        return self.chunks[0]

    def _restore_chunks(self, state: dict, keys: tuple, flat: tuple = ()) -> int:
        """The map of ``state`` (float32 arrays ``keys``, (m, 3) or (m,) for
        those in ``flat``) as the only chunk; returns its length."""
        got = []
        for key in keys:
            a = state.get(key)
            ndim = 1 if key in flat else 2
            if not isinstance(a, np.ndarray) or a.dtype != np.float32 or a.ndim != ndim or \
                    (ndim == 2 and a.shape[1] != 3):
                raise OclgiError(f"run state: {self.name} expects {key!r} as float32 "
                                 f"{'(m,)' if ndim == 1 else '(m, 3)'}")
            got.append(np.ascontiguousarray(a))
        if len({len(a) for a in got}) != 1:
            raise OclgiError(f"run state: {self.name}'s {self.what} arrays differ in length")
        if len(got[0]) > self.limit:
            raise OclgiError(f"run state: {len(got[0]):,} {self.what}s, more than this device holds "
                             f"({self.limit:,})")
        self.chunks = [tuple(got)] if len(got[0]) else []
        return len(got[0])

    def radii(self) -> np.ndarray:
        """r_k per point (inf where fewer than k neighbours were found), after resolve."""
        return np.sqrt(read_buffer(self.queue, self.r2, self.n, np.float32))

    def work(self) -> dict | None:
        """Work of the search (u: distance tests of impacts or segment
        pieces, nodes: BVH nodes visited)."""
        return super().work() if not self.count_work or self.knn is None else self.knn.work()


class PhotonMap(KnnMap):
    """The estimator (module docstring): gathers impacts batch by batch,
    searches at ``resolve``; ``impacts``, ``neighbours`` and ``radii``
    expose the map for tests and studies."""

    name = "photon_map"
    family = "photon_map"
    # Exact add/subtract does not apply to k nearest neighbours (a removed
    # impact changes other points' neighbour sets); see DESIGN.md section 4.
    incremental = False

    def __init__(self, queue, compiled, points, k: int = DEFAULT_K, estimator: str = "k-1",
                 front_only: bool = True, leaf_size: int = 16, radius=None, extension=None, **kw):
        # radius and extension are DETP parameters; the k-th neighbour sets the radius here
        super().__init__(queue, compiled, points, **kw)
        check_k(k, estimator)
        check_leaf_size(leaf_size)
        if not isinstance(front_only, (bool, np.bool_)):
            raise OclgiError(f"photon_map: front_only must be true or false, got {front_only!r}")
        self.k, self.estimator = int(k), estimator
        self.front_only, self.leaf_size = bool(front_only), leaf_size
        self.limit = max_impacts(queue.device)
        prog = programs(self.ctx).get("photon_map")  # compaction and resolve do not depend on k
        self.k_count, self.k_gather, self.k_resolve = prog.pm_count, prog.pm_gather, prog.pm_resolve
        self.positions, self.normals, self.order, self.acc, self.r2, self.irr = point_buffers(self, points)
        self.chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.n_impacts = 0
        self.knn: KnnIndex | None = None

    # -- gathering ---------------------------------------------------------
    def accumulate(self, batch):
        n_paths = batch.n_paths
        counts_buf = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, n_paths * 4)
        c = self.compiled
        args = (batch.segments, n_paths, batch.max_depth, int(self.count_emitted), c.tri_material, c.materials)
        launch(self.queue, self.k_count, n_paths, *args, counts_buf, local_size=self.local_size)
        counts = read_buffer(self.queue, counts_buf, n_paths, np.int32)
        offsets = np.zeros(n_paths, np.int64)
        np.cumsum(counts[:-1], out=offsets[1:])
        m = int(offsets[-1] + counts[-1])
        self._check_room(self.n_impacts + m)
        if m == 0:
            return
        mf = cl.mem_flags
        off_buf = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=offsets.astype(np.int32))
        bufs = [cl.Buffer(self.ctx, mf.WRITE_ONLY, m * 12) for _ in range(3)]
        launch(self.queue, self.k_gather, n_paths, *args, off_buf, *bufs, local_size=self.local_size)
        self.chunks.append(tuple(read_buffer(self.queue, b, (m, 3), np.float32) for b in bufs))
        self.n_impacts += m
        self.knn = None  # indexes the impacts gathered before these

    def first_batch(self, paths_done: int, paths_total: int, segments: int) -> None:
        self._check_projected(self.n_impacts, paths_done, paths_total)

    def state(self) -> dict:
        """A Photon Map's state is its impacts (the sums come at the search)."""
        return dict(zip(IMPACT_KEYS, self.impacts()))

    def restore(self, state: dict) -> None:
        self.n_impacts, self.knn = self._restore_chunks(state, IMPACT_KEYS), None

    def clear_impacts(self):
        """Forget the gathered impacts and their index (a session gathers its
        store again after a move); the sums and radii stay."""
        self.chunks, self.n_impacts, self.knn = [], 0, None

    def impacts(self):
        """All impacts in canonical order: positions, directions, powers, (N, 3) float32."""
        z = np.zeros((0, 3), np.float32)
        return self._joined((z, z, z))

    # -- the estimate ---------------------------------------------------------
    def build_index(self) -> KnnIndex:
        if self.knn is None:
            if self.n_impacts < self.k:
                raise OclgiError(f"photon_map: only {self.n_impacts:,} impacts for k = {self.k}; "
                                 f"trace more photons or lower k")
            pos, dirs, pw = self.impacts()
            self.knn = KnnIndex(self.queue, pos, dirs, pw, leaf_size=self.leaf_size, count_work=self.count_work)
        return self.knn

    def search(self, ids: np.ndarray | None = None):
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
                   self.estimator == "k", self.acc, self.r2, local_size=self.local_size)

    def irradiance_buffer(self, scale: float) -> cl.Buffer:
        """E = acc / (scale pi r_k^2) from the current sums and radii (float4 per point, on the device)."""
        launch(self.queue, self.k_resolve, self.n, self.acc, self.r2, self.n,
               1.0 / (scale * math.pi), self.irr)
        return self.irr

    def resolve(self, scale: float) -> cl.Buffer:
        """Irradiance (float4 per point, on the device): E = acc / (scale pi r_k^2)."""
        self.search()
        return self.irradiance_buffer(scale)

    def replace_points(self, index: np.ndarray, new) -> None:
        """Points ``index`` moved (points on a moved object); the caller searches them again.
        The Morton order of the full search is kept: it only serves locality."""
        self.move_points(index, new)

    def neighbours(self, k: int | None = None):
        """The k nearest front-side impacts of this estimator's points (ids
        in canonical order, see ``impacts``), as KnnIndex.neighbours."""
        k = self.k if k is None else k
        return self.build_index().neighbours(self.points.positions[:, :3], self.points.normals[:, :3], k,
                                             self.front_only)
