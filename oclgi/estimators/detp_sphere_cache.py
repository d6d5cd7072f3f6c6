"""DETP with a sphere cache (Lastra 2002b; cost model García 2006).

Plain DETP tests every segment against every disc. The sphere cache visits
the query points along a space-filling curve (oclgi/accel/ordering.py) and keeps,
around the last point, a stack of nested spheres ``S_0 ⊃ S_1 ⊃ ... ⊃ S_L``
of radii ``R_k = R_L Q^(k-L)``, each with the list of segments that meet it.
For the next disc (centre x, radius d) it finds the deepest ``j`` such that
``S_1 .. S_j`` all still hold the whole disc (``|x - c_k| + d <= R_k``),
re-centres ``S_j+1 .. S_L`` on x, rebuilds each list by testing its
parent's list (segment-sphere test: distance from the centre to the segment
``[o, o + (t_end + e) w] <= R``), and applies the DETP test (kernels/
detp.h, the one shared definition) to the innermost list only. Results are
identical to plain DETP, bit for bit (kernels/detp_sphere_cache.cl says why
the tests are conservative enough).

Points go in runs of ``run_length`` consecutive points of the curve, one
work-item each, every run with its own stack (the thesis' single traversal
is one run). Within a run the order is the curve's, so results and counts
do not depend on how runs are scheduled. Points without a normal (camera
pixels that see nothing) can receive nothing: they are skipped, uncounted.

Spheres. ``S_0`` is fixed per estimator: the sphere on the query points'
bounding box, grown by d, so it holds every disc (a sphere on the segments
would be infinite: escaping segments have t_end = inf); each batch's
segments are filtered against it once (``sc_gather``), giving list 0. The
innermost radius is the cost model's: ``R_L = max(d, R_0 / cbrt(n_P))``,
about the point spacing h (deeper spheres would be rebuilt at nearly every
point, and a rebuild costs more than the segment-disc tests it saves). The
stack is anchored there, ``R_k = R_L Q^(k-L)`` with ``L`` the largest count
for which ``R_1 <= Q R_0`` (at most MAX_LEVELS), so the deep levels, which
dominate the cost, have the model's radii for every Q.

Cost model (García 2006; DESIGN.md 3), n_R segments, n_P points in a
volume, ``t``/``u`` the costs of a segment-sphere/segment-disc test::

    T = t n_R / Q^2 (cbrt(n_P) - 1) / (1 - Q)  +  4/3 u n_R cbrt(n_P)

Level k (``R_k = R_0 Q^k``) is rebuilt about ``n_P (h / R_k)^3`` times (the
curve stays in a sphere for as many points as it holds) from a parent list
of about ``n_R (R_k-1 / R_0)^2`` segments; the sum over levels is the first
term, least where ``Q^2 (1 - Q)`` is largest: ``Q = 2/3``.

With the disc radius. A sphere holds the disc only while ``|x - c| <= R - d``,
so level k is rebuilt about ``n_P (h / (R_k - d))^3`` times, and the cost
per level, ``g(R) = R^2 / (R - d)^3`` (times Q^-2), grows toward the bottom
like ``R^-a`` with ``a = 3 R / (R - d) - 2`` (``a = 1`` for ``d << R``). The
geometric sum is dominated by its deepest terms, ``T_t ~ Q^-2 / (1 - Q^a)``,
least at ``Q* = (2 / (2 + a))^(1/a)``: 2/3 for discs much smaller than the
innermost sphere, 0.71 for ``a = 2`` (``R_L = 4d``), 0.74 for ``a = 3``
(``R_L = 3d``), tending to 1 as ``R_L -> d``: larger discs want a larger Q.
Measured counts (t + u, bunny box, 32,768 points in its volume, Hilbert
order, one run; tests/test_detp_sphere_cache.py has the first): the argmin
over Q = 0.40, 0.45 .. 0.90 is 0.60 for d = h/160, 0.65 for d = 0.6 h and
2 h, 0.75 for d = 6 h. For tiny discs the optimum sits below 2/3 because,
for the R/h <= 40 of such runs, the measured rebuild rates go like
``(h / R)^2``, not ``(h / R)^3`` (a Hilbert walk leaves a sphere centred on
one of its points after ~(R/h)^2 points): then every level costs the same,
``T_t ~ Q^-2 / ln(1/Q)``, least at ``Q = e^-1/2 = 0.61``.

Parameters (besides DetpEstimator's radius, extension, count_emitted):

============ ========== =======================================================
parameter    default    meaning
============ ========== =======================================================
q            2/3        ratio of consecutive radii, 0 < q < 1
order        "hilbert"  point order: "hilbert", "morton" or "none" (input order)
run_length   None       points per work-item (a run keeps its own spheres);
                        None: n_P / (RUNS_PER_UNIT x compute units), at least
                        MIN_RUN. Longer runs re-use spheres more (a cold start
                        costs ~2 n_R tests); shorter runs give more parallelism.
============ ========== =======================================================

Memory is bounded, nothing is of size n_R x n_P: list 0 holds at most the
batch's segments (ENTRY_BYTES each), and every run in flight has a stack of
``cap`` entries for its lists (copies of segment records: the deep lists
stay contiguous and in cache); runs go in waves of at most SCRATCH_BYTES /
(ENTRY_BYTES cap) work-items. ``cap`` starts from the previous batch's peak,
the expected list sizes or an equal share of SCRATCH_BYTES, whichever is
largest; a run that would pass it stops before the point, and the
unfinished runs are run again with a larger cap (never more than
L x |list 0|, which cannot overflow), so no segment is ever dropped and sums
and work counts equal those of a run without overflow. Measured: 10^6
points and 10^6 segments (Cornell box) peak at 1.0 GiB of process memory.
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from ..accel import ordering
from ..cl.constants import SC_MAX_LEVELS as MAX_LEVELS
from ..cl.constants import SC_MU as MU  # noqa: F401  (the slack of the kernel's sphere test, for host checks)
from ..cl.layout import ScRecord
from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError
from .base import DetpEstimator

ENTRY_BYTES = ScRecord.itemsize + 4  # a list entry: a segment record and its slot (int)
PATHS_PER_ITEM = 64  # paths per sc_gather work-item
SCRATCH_BYTES = 512 << 20  # scratch for the lists of the runs in flight
RUNS_PER_UNIT = 4  # default runs per compute unit: enough to balance uneven runs (measured: 4 per unit best)
MIN_RUN = 64  # default runs are at least this long: a cold start costs ~n_R tests


def sphere_radii(half_diagonal: float, d: float, n_points: int, q: float) -> np.ndarray:
    """Radii R_0 .. R_L (float64): R_0 holds every disc, R_L = max(d, R_0 / cbrt(n_P))."""
    # R_0 a hair larger than the bounding sphere of the discs, so float
    # rounding cannot put a disc outside it.
    r0 = (half_diagonal + d) * (1 + 1e-5) + 1e-30
    r_in = max(d, (half_diagonal + d) / max(n_points, 1) ** (1 / 3))
    levels = 0
    if r_in < r0 * q:
        levels = int(math.floor(math.log(r0 / r_in) / math.log(1 / q) + 1e-9))
    levels = min(levels, MAX_LEVELS)
    inner = [r_in * q ** (k - levels) for k in range(1, levels + 1)]
    return np.array([r0, *inner], np.float64)


class DetpSphereCache(DetpEstimator):
    name = "detp_sphere_cache"

    def __init__(self, queue, compiled, points, radius: float, q: float = 2 / 3, order: str = "hilbert",
                 run_length: int | None = None, **kw):
        if isinstance(q, bool) or not isinstance(q, (int, float)) or not 0.0 < q < 1.0:
            raise OclgiError(f"sphere cache q must be a number in (0, 1), got {q!r}")
        ordering.check_method(order)
        if run_length is not None and (isinstance(run_length, bool) or not isinstance(run_length, (int, np.integer))
                                       or run_length < 1):
            raise OclgiError(f"run_length must be a positive integer, got {run_length!r}")
        super().__init__(queue, compiled, points, radius, **kw)
        self.q, self.order = float(q), order
        prog = programs(self.ctx).get("detp_sphere_cache", **self.defines)
        self.k_gather, self.k_runs = prog.sc_gather, prog.sc_runs

        # Points without a normal (camera pixels that see nothing, placed at
        # the origin) receive nothing and are skipped by the kernel: they do
        # not count in the spheres' sizes, nor in the order.
        xyz = points.xyz
        real = np.any(points.normals[:, :3] != 0, axis=1)
        live = xyz[real] if real.any() else xyz[:1]
        lo, side = ordering.bounding_cube(live)
        hi = np.array([live[:, c].max() for c in range(3)], np.float64)
        centre = (lo + hi) / 2
        half_diag = float(np.linalg.norm(hi - lo)) / 2
        self.radii = sphere_radii(half_diag, self.radius, max(1, int(real.sum())), self.q)
        self.levels = len(self.radii) - 1
        self.c0 = np.array([*centre, 0.0], np.float32)
        self.radii_buf = self.upload(self.radii.astype(np.float32))
        self.perm = ordering.order_points(queue, xyz, order, box=(lo, side), device=True)

        units = queue.device.max_compute_units
        if run_length is None:
            run_length = max(MIN_RUN, -(-self.n // (RUNS_PER_UNIT * units)))
        self.run_length = int(min(run_length, self.n))
        self.n_runs = -(-self.n // self.run_length)
        self.all_runs = self.upload(np.arange(self.n_runs, dtype=np.int32))
        self.run_done = self.zeros(self.n_runs * 4)  # per run: points done (of the current piece)
        self.status = self.zeros(3 * 4)
        dev = queue.device
        self.scratch_bytes = int(min(SCRATCH_BYTES, dev.max_mem_alloc_size))
        self._rec0 = self._slot0 = self._srec = self._sslot = None
        self._n0 = self.zeros(4)
        self._peak_per_segment = None  # stack peak / |list 0| of the last batch
        # The runs are few and long and uneven (runs near a light meet more
        # segments): one work-item per work-group lets the runtime balance
        # them over the cores. Results do not depend on it.
        self.run_local_size = self.local_size or 1

    # -- helpers ----------------------------------------------------------------
    def _buffer(self, attr: str, nbytes: int) -> cl.Buffer:
        buf = getattr(self, attr)
        if buf is None or buf.size < nbytes:
            buf = cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE, max(nbytes, 8))
            setattr(self, attr, buf)
        return buf

    def _initial_cap(self, n0: int) -> int:
        """Stack capacity (entries) per run for a batch with |list 0| = n0.

        Overflow is exact but costs a rerun, so be generous: the previous
        batch's peak (scaled to n0), or the cross-section estimate
        |list k| ~ n0 (R_k / R_0)^2, or an equal share of the scratch budget
        for every run, whichever is largest; never more than L n0, which
        cannot overflow. (Segments crowd near the lights: the cross-section
        estimate alone was 2.6 times short on the Cornell box.)
        """
        most = max(1, self.levels * n0)
        if self._peak_per_segment is not None:
            guess = self._peak_per_segment * n0 * 1.25
        else:
            fr = np.minimum(1.0, (self.radii[1:] / self.radii[0]) ** 2)
            guess = 1.5 * n0 * float(fr.sum())
        share = self.scratch_bytes // (ENTRY_BYTES * self.n_runs) - 1
        return int(min(most, max(1024, guess, share)))

    # -- the estimator ------------------------------------------------------------
    def accumulate(self, batch):
        q = self.queue
        rec0 = self._buffer("_rec0", batch.n_slots * ScRecord.itemsize)
        slot0 = self._buffer("_slot0", batch.n_slots * 4)
        cl.enqueue_copy(q, self._n0, np.zeros(1, np.int32))  # a fill costs ~0.4 ms on PoCL
        launch(q, self.k_gather, -(-batch.n_paths // PATHS_PER_ITEM), batch.segments, batch.n_paths,
               batch.max_depth, self.count_emitted, PATHS_PER_ITEM, self.c0,
               self.radii[0], self.ext, rec0, slot0, self._n0, self.work_buf,
               local_size=self.local_size)
        n0 = int(read_buffer(q, self._n0, 1, np.int32)[0])
        if n0 == 0:
            return

        # Work list of pieces of list 0: (first record, count, how far each
        # run got). Normally one piece. Sums and counts are additive over
        # segments and the sphere decisions do not depend on them, so a
        # piece whose lists cannot fit even alone in the scratch is split in
        # two, each half resuming every run where the piece left it: same
        # sums, same counts, bounded memory.
        lengths = np.minimum(self.run_length, self.n - np.arange(self.n_runs) * self.run_length)
        max_cap = self.scratch_bytes // ENTRY_BYTES - 1
        cap = min(max_cap, self._initial_cap(n0))
        todo = [(0, n0, np.zeros(self.n_runs, np.int32))]
        peak = 0.0
        while todo:
            first, count, done = todo.pop()
            most = max(1, self.levels * count)  # lists are subsets of the piece: this cannot overflow
            cap = min(cap, most, max_cap)
            cl.enqueue_copy(q, self.run_done, done)
            pending = np.nonzero(done < lengths)[0].astype(np.int32)
            runs, n_pending = (self.all_runs if len(pending) == self.n_runs else self.upload(pending)), len(pending)
            while n_pending:
                cl.enqueue_copy(q, self.status, np.zeros(3, np.int32))
                wave = max(1, min(n_pending, self.scratch_bytes // ((cap + 1) * ENTRY_BYTES)))
                srec = self._buffer("_srec", wave * (cap + 1) * ScRecord.itemsize)
                sslot = self._buffer("_sslot", wave * (cap + 1) * 4)
                for base in range(0, n_pending, wave):
                    launch(q, self.k_runs, min(wave, n_pending - base), self.positions, self.normals, self.perm,
                           self.n, self.run_length, runs, base,
                           min(wave, n_pending - base), self.run_done, rec0, slot0, first,
                           count, batch.segments, self.radii_buf, self.levels,
                           self.radius, self.radius**2, srec, sslot,
                           cap, self.acc, self.status, self.work_buf, local_size=self.run_local_size)
                st = read_buffer(q, self.status, 3, np.int32)
                peak = max(peak, st[2] / count)
                if st[0] == 0:
                    break
                # Some runs stopped before a point whose lists did not fit.
                cl.enqueue_copy(q, done, self.run_done)
                pending = np.nonzero(done < lengths)[0].astype(np.int32)
                runs, n_pending = self.upload(pending), len(pending)
                if cap < min(most, max_cap):
                    # room for at least what they met, and then some
                    cap = int(min(most, max_cap, max(2 * cap, 1.25 * st[1])))
                else:
                    half = count // 2
                    todo += [(first, half, done.copy()), (first + half, count - half, done.copy())]
                    break
        self._peak_per_segment = max(peak, 1.0 / n0)
