"""DETP: density estimation on the tangent plane (Lastra et al. 2002), plain.

For a query point x with unit normal n, the disc of radius d centred on x in
the tangent plane collects the power of every segment crossing it from the
front (kernels/detp.h has the one definition). E(x) = sum / (pi d^2).

Parameters: ``radius`` d; ``extension`` e (segments may end up to e past the
disc's plane and still count; for concave surfaces); ``count_emitted``
(segments leaving the lights count, i.e. direct light included).
Cost O(n_R n_P): the oracle the accelerated variants must equal bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from ..cl.programs import launch, programs

LANES = 8  # points per work-item in detp_plain (kernels/detp.cl)


class Detp:
    name = "detp"

    def __init__(self, queue, compiled, points, radius: float, extension: float = 0.0,
                 count_emitted: bool = True, local_size: int | None = None):
        self.queue = queue
        self.compiled = compiled
        self.n = len(points)
        self.radius = float(radius)
        # The user's extension plus a scene-relative tolerance, so segments
        # ending on the disc's own surface survive float rounding.
        self.ext = float(extension) + 10.0 * compiled.eps
        self.count_emitted = bool(count_emitted)
        self.local_size = local_size
        ctx = queue.context
        prog = programs(ctx).get("detp")
        self.k_plain, self.k_resolve = prog.detp_plain, prog.detp_resolve
        mf = cl.mem_flags
        self.positions = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=points.positions)
        self.normals = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=points.normals)
        self.acc = cl.Buffer(ctx, mf.READ_WRITE, max(1, self.n) * 3 * 8)
        cl.enqueue_fill_buffer(queue, self.acc, np.int64(0), 0, max(1, self.n) * 3 * 8)
        self.irr = cl.Buffer(ctx, mf.READ_WRITE, max(1, self.n) * 16)

    def accumulate(self, batch, scale: float):
        launch(
            self.queue, self.k_plain, (self.n + LANES - 1) // LANES,
            self.positions, self.normals, np.int32(self.n), batch.segments, np.int32(batch.n_paths),
            np.int32(batch.max_depth), np.int32(self.count_emitted), np.float32(self.radius**2),
            np.float32(self.ext), np.float32(scale), self.acc,
            local_size=self.local_size,
        )

    def resolve(self, scale: float) -> cl.Buffer:
        """Irradiance (float4 per point, on the device)."""
        inv = 1.0 / (scale * math.pi * self.radius**2)
        launch(self.queue, self.k_resolve, self.n, self.acc, np.int32(self.n), np.float32(inv), self.irr)
        return self.irr

    def accumulators(self) -> np.ndarray:
        out = np.empty((self.n, 3), np.int64)
        cl.enqueue_copy(self.queue, out, self.acc)
        return out
