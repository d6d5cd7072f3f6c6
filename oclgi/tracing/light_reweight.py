"""A light animation's frames as re-weightings (driver of ``kernels/light_reweight.cl``).

Path reuse (oclgi/tracing/light_reuse.py) makes frame j of a light
animation an ordinary batch of the stored paths: segment 0 new (from the
frame's light position to the stored first hit), the tail's segments as
stored with their powers times one factor per path. An estimator that sums
per segment (every DETP variant) then runs each frame over every tail
segment again, although where they cross the discs never changes: only
their weights do. ``Reweighting`` finds, once, every (disc, tail segment)
pair the estimator's test accepts (the disc index's walk), and a frame is
then segment 0 of every path through the estimator plus one pass over the
pairs, each adding its segment's stored power times its path's factor,
quantised as the frame's own segment would be. The sums equal
``LightReuse.estimate``'s bit for bit.

Memory: 8 bytes per pair, bounded by the count of accepted segment-disc
pairs of one frame's tails (refused beyond one device buffer); time per
frame: the direct segments' estimate plus O(pairs). Whether that pays
depends on the pairs per tail segment (bench/light_reuse.py measures it).
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError


class Reweighting:
    """The pairs of a ``LightReuse`` animation's tails with the discs of
    ``estimator`` (a ``detp_disc_index`` estimator from ``reuse.estimator``)."""

    def __init__(self, reuse, estimator):
        if estimator.name != "detp_disc_index":
            raise OclgiError(f"re-weighting takes a detp_disc_index estimator (its disc index finds the pairs), "
                             f"got {estimator.name}")
        self.reuse, self.estimator = reuse, estimator
        q, ctx = reuse.queue, reuse.queue.context
        t0 = time.perf_counter()
        self.prog = programs(ctx).get("light_reweight", **estimator.defines)
        n, md = reuse.n_paths, reuse.max_depth
        self.n_pairs = 0
        mf = cl.mem_flags
        self.scales = cl.Buffer(ctx, mf.READ_WRITE, max(n, 1) * 4)
        if estimator.nodes is None:  # no disc to cross
            self.pair_disc = self.pair_slot = None
            self.seconds = time.perf_counter() - t0
            return
        counts = cl.Buffer(ctx, mf.READ_WRITE, n * 4)
        args = (estimator.nodes, estimator.blocks, reuse.store, n, md, estimator.ext)
        launch(q, self.prog.reweight_count, n, *args, counts, local_size=reuse.engine.local_size)
        host = read_buffer(q, counts, n, np.int32)
        offsets = np.zeros(n, np.int64)
        np.cumsum(host[:-1], out=offsets[1:])
        self.n_pairs = int(host.sum(dtype=np.int64))
        limit = q.device.max_mem_alloc_size
        if self.n_pairs * 4 > limit:
            raise OclgiError(f"{self.n_pairs:,} segment-disc pairs need more than one device buffer holds "
                             f"({limit / 2**30:.2f} GiB); re-weighting does not pay here")
        self.pair_disc = cl.Buffer(ctx, mf.READ_WRITE, max(self.n_pairs, 1) * 4)
        self.pair_slot = cl.Buffer(ctx, mf.READ_WRITE, max(self.n_pairs, 1) * 4)
        off = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=offsets)
        launch(q, self.prog.reweight_fill, n, *args, off, self.pair_disc, self.pair_slot,
               local_size=reuse.engine.local_size)
        q.finish()
        self.seconds = time.perf_counter() - t0

    def accumulate(self, frame: int) -> None:
        """Frame ``frame``'s sums into the estimator (added to what it holds):
        segment 0 of every path through it, the tails by the pairs."""
        r, est = self.reuse, self.estimator
        for batch in r.batches(frame, tails=False):
            est.accumulate(batch)
        if not self.n_pairs:
            return
        c = r.compiled
        launch(r.queue, self.prog.reweight_scales, r.n_paths, c.tri_normals, r.lights, c.emitter_cdf, int(frame),
               r.paths_per_position, r.store, r.density_sum, r.visible, r.words, r.n_paths, r.max_depth,
               self.scales, local_size=r.engine.local_size)
        launch(r.queue, self.prog.reweight_add, self.n_pairs, r.store, r.max_depth, self.pair_disc, self.pair_slot,
               self.n_pairs, self.scales, est.acc, local_size=r.engine.local_size)
