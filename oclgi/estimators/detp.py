"""DETP: density estimation on the tangent plane (Lastra et al. 2002), plain.

For a query point x with unit normal n, the disc of radius d centred on x in
the tangent plane collects the power of every segment crossing it from the
front (kernels/detp.h has the one definition). E(x) = sum / (pi d^2).
Cost O(n_R n_P): the oracle the accelerated variants must equal bit for bit.
Parameters: see :class:`oclgi.estimators.base.DetpEstimator`.
"""

from __future__ import annotations

import math

from ..cl.layout import Segment
from ..cl.constants import LANES  # points per work-item in detp_plain (kernels/detp.cl)
from ..cl.programs import launch, timed_slices
from .adaptive_radius import AdaptiveRadii
from .base import DetpEstimator


# Point-path pairs in the first piece of a batch, before one is timed.
FIRST_PAIR_TESTS = 1 << 24


class Detp(DetpEstimator):
    name = "detp"
    radii_maker = AdaptiveRadii  # detp_plain reads each point's d^2

    def __init__(self, queue, compiled, points, radius: float, **kw):
        super().__init__(queue, compiled, points, radius, **kw)
        self.k_plain = self.program("detp").detp_plain

    def accumulate(self, batch):
        # Each work-item loops over every path of the batch: sliced by
        # work-item, one slice would still hold all the paths (seconds at a
        # few thousand points). The batch is run in pieces of paths instead
        # (cl.programs.timed_slices), each through a sub-buffer of the
        # segments: the sums are integer adds, in any order the same.
        align = self.queue.device.mem_base_addr_align // 8  # a sub-buffer's start, in bytes
        path_bytes = batch.max_depth * Segment.itemsize
        unit = align // math.gcd(align, path_bytes)
        first = max(1, FIRST_PAIR_TESTS // max(self.n, 1))
        # A path costs in proportion to the points: the slice size is per point count.
        for start, count in timed_slices(self.queue, ("detp_plain", self.n), batch.n_paths, unit, first):
            segments = batch.segments if count == batch.n_paths else batch.segments.get_sub_region(
                start * path_bytes, count * path_bytes)
            launch(self.queue, self.k_plain, (self.n + LANES - 1) // LANES, self.positions, self.normals, self.n,
                   segments, count, batch.max_depth, self.count_emitted, self.radius2_buf, self.ext, self.acc,
                   self.work_buf, local_size=self.local_size)
