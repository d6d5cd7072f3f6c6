"""Every segment of every path, kept on the device, and the steps of an
incremental update over it (DESIGN.md section 4; kernels/update.cl).

A store is traced once: ``photons`` paths of up to ``max_depth`` segments,
path-major, as one batch. After a movable object moves:

1. ``find`` lists, per path, the first segment that hit the object at its
   old pose or meets it at its new pose (the earlier segments are the same
   in the moved scene);
2. ``suffixes(affected, -1)`` gathers the affected suffixes with negated
   power into a scratch batch: accumulated by an estimator, they take their
   old contributions away exactly (fixed-point sums);
3. ``retrace(affected)`` re-traces the suffixes in place, with the same code
   and random numbers as a full trace;
4. ``suffixes(affected, +1)`` gathers the new suffixes, to be added.

Sessions (oclgi/session.py) drive these steps for their estimators.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .cl.layout import Segment
from .cl.programs import launch, programs
from .errors import OclgiError
from .photon_trace import PathBatch, PhotonTracer


@dataclass
class Affected:
    """Paths a move touches: ids and first affected bounce, on host and device."""

    paths: np.ndarray  # int32, path ids
    starts: np.ndarray  # int32, first affected bounce of each
    paths_buf: cl.Buffer | None = None
    starts_buf: cl.Buffer | None = None

    def __len__(self):
        return len(self.paths)


class SegmentStore:
    """``photons`` paths traced with ``seed`` and ``max_depth`` on the engine's scene."""

    def __init__(self, engine, photons: int, seed: int, max_depth: int):
        self.engine = engine
        self.queue = engine.queue
        self.photons, self.max_depth = int(photons), int(max_depth)
        nbytes = self.photons * self.max_depth * Segment.itemsize
        limit = engine.queue.device.max_mem_alloc_size
        if nbytes > limit:
            raise OclgiError(f"a session keeps every segment: {self.photons:,} paths x {self.max_depth} slots "
                             f"need {nbytes / 2**30:.2f} GiB, more than one device allocation "
                             f"({limit / 2**30:.2f} GiB); use fewer photons or a smaller max_depth")
        self.nbytes = nbytes
        self.scale = engine.compiled.fixed_scale(self.photons)
        self.tracer = PhotonTracer(self.queue, engine.compiled, seed, max_depth, self.photons, engine.local_size)
        self.batch = self.tracer.trace(0, self.photons, self.photons)
        prog = programs(engine.ctx).get("update")
        self.k_first, self.k_gather = prog.update_first_affected, prog.update_gather
        self.first = cl.Buffer(engine.ctx, cl.mem_flags.READ_WRITE, self.photons * 4)
        self.first_host = np.empty(self.photons, np.int32)
        self.scratch = None  # grown on demand: gathered suffixes

    # -- reading ------------------------------------------------------------
    def segments(self) -> np.ndarray:
        """The stored segments (``Segment`` array, path-major), on the host."""
        return self.batch.read_segments(self.queue)

    def path_len(self) -> np.ndarray:
        return self.batch.read_path_len(self.queue)

    # -- updating -----------------------------------------------------------
    def find(self, obj: int, discs=None) -> Affected:
        """Paths touched by the move of object ``obj`` (already placed at its
        new pose). With ``discs`` (a DetpDiscIndex) the same pass over the
        store also sums every stored segment into its points' accumulators."""
        engine, q = self.engine, self.queue
        args = (*engine.compiled.scene_args, np.int32(obj), self.batch.segments, np.int32(self.photons),
                np.int32(self.max_depth), self.first)
        if discs is None or discs.nodes is None:
            launch(q, self.k_first, self.photons, *args, local_size=engine.local_size)
        else:
            k = programs(engine.ctx).get("update", **discs.defines).update_first_affected_discs
            launch(q, k, self.photons, *args, discs.nodes, discs.blocks, np.int32(discs.count_emitted),
                   np.float32(discs.radius ** 2), np.float32(discs.ext), np.float32(self.scale), discs.acc,
                   discs.work_buf, local_size=engine.local_size)
        cl.enqueue_copy(q, self.first_host, self.first)
        paths = np.nonzero(self.first_host >= 0)[0].astype(np.int32)
        affected = Affected(paths, self.first_host[paths].copy())
        if len(paths):
            mf = cl.mem_flags
            affected.paths_buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=affected.paths)
            affected.starts_buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=affected.starts)
        return affected

    def suffix_segments(self, affected: Affected) -> int:
        """Stored segments in the affected suffixes (n_Rec of this update)."""
        if not len(affected):
            return 0
        return int((self.path_len()[affected.paths] - affected.starts).sum())

    def suffixes(self, affected: Affected, sign: float) -> PathBatch:
        """The affected suffixes, power times ``sign``, as a batch of
        len(affected) paths; the slots before each suffix are holes."""
        n = len(affected)
        nbytes = n * self.max_depth * Segment.itemsize
        if self.scratch is None or self.scratch.size < nbytes:
            # grow geometrically, never past the store itself
            size = max(nbytes, min(2 * (self.scratch.size if self.scratch else 0), self.nbytes))
            self.scratch = cl.Buffer(self.engine.ctx, cl.mem_flags.READ_WRITE, size)
        launch(self.queue, self.k_gather, n, self.batch.segments, np.int32(self.max_depth), affected.paths_buf,
               affected.starts_buf, np.int32(n), np.float32(sign), self.scratch)
        # Path ids stay in the gathered slots; the scratch is a batch like any other.
        return PathBatch(self.scratch, self.batch.path_len, 0, n, self.max_depth)

    def retrace(self, affected: Affected):
        """Re-trace the affected suffixes in place (the scene already moved)."""
        self.tracer.retrace(self.batch, self.photons, affected.paths_buf, affected.starts_buf, len(affected))
