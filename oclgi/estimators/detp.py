"""DETP: density estimation on the tangent plane (Lastra et al. 2002), plain.

For a query point x with unit normal n, the disc of radius d centred on x in
the tangent plane collects the power of every segment crossing it from the
front (kernels/detp.h has the one definition). E(x) = sum / (pi d^2).
Cost O(n_R n_P): the oracle the accelerated variants must equal bit for bit.
Parameters: see :class:`oclgi.estimators.base.DetpEstimator`.
"""

from __future__ import annotations


from ..cl.constants import LANES  # points per work-item in detp_plain (kernels/detp.cl)
from ..cl.programs import launch
from .base import DetpEstimator


class Detp(DetpEstimator):
    name = "detp"

    def __init__(self, queue, compiled, points, radius: float, **kw):
        super().__init__(queue, compiled, points, radius, **kw)
        self.k_plain = self.program("detp").detp_plain

    def accumulate(self, batch, scale: float):
        launch(
            self.queue, self.k_plain, (self.n + LANES - 1) // LANES,
            self.positions, self.normals, self.n, batch.segments, batch.n_paths,
            batch.max_depth, self.count_emitted, self.radius**2,
            self.ext, scale, self.acc, self.work_buf,
            local_size=self.local_size,
        )
