"""Photon tracing on the device (driver of ``kernels/photon_trace.cl``).

Paths are traced in batches of at most ``batch_paths`` so that a run of any
size fits in device memory: each batch is traced into one reused segment
buffer and handed to the estimators before the next. Batching changes
nothing in the result: a path's randomness depends only on (seed, path id),
and sums are fixed point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ..cl.layout import Segment
from ..cl.programs import launch, programs, read_buffer


@dataclass
class PathBatch:
    segments: cl.Buffer  # Segment[n_paths * max_depth], path-major
    path_len: cl.Buffer  # int[n_paths]
    path_offset: int  # global id of the batch's first path
    n_paths: int
    max_depth: int
    retraced: int = 0  # suffix re-traces so far (PhotonTracer.retrace): a version of the segments

    @property
    def n_slots(self) -> int:
        return self.n_paths * self.max_depth

    def read_segments(self, queue) -> np.ndarray:
        return read_buffer(queue, self.segments, self.n_slots, Segment)

    def read_path_len(self, queue) -> np.ndarray:
        return read_buffer(queue, self.path_len, self.n_paths, np.int32)


class PhotonTracer:
    def __init__(self, queue: cl.CommandQueue, compiled, seed: int, max_depth: int,
                 batch_paths: int, local_size: int | None = None):
        self.queue, self.compiled, self.local_size = queue, compiled, local_size
        self.seed, self.max_depth, self.batch_paths = int(seed), int(max_depth), int(batch_paths)
        ctx = queue.context
        prog = programs(ctx).get("photon_trace")
        self.kernel, self.k_retrace = prog.photon_trace, prog.photon_retrace
        self.segments = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, self.batch_paths * self.max_depth * Segment.itemsize)
        self.path_len = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, self.batch_paths * 4)
        self.launches = 0  # trace and retrace launches so far (what a session's switches must not add to)

    def _trace_args(self) -> tuple:
        """TRACE_ARGS of kernels/photon_trace.cl."""
        c = self.compiled
        return (c.tri_normals, c.tri_material, c.materials, c.tri_uvmap, c.tri_colourmap, c.tri_object, c.textures, c.texels,
                c.emitters, c.emitter_cdf, c.n_emitters,
                self.seed & 0xFFFFFFFF, self.seed >> 32, self.max_depth, c.eps)

    def trace(self, path_offset: int, n_paths: int) -> PathBatch:
        """Paths path_offset .. path_offset + n_paths - 1 (global ids); a
        path's segments do not depend on the batch or the run's total."""
        assert 0 < n_paths <= self.batch_paths
        self.launches += 1
        launch(self.queue, self.kernel, n_paths, *self.compiled.scene_args, *self._trace_args(),
               path_offset, n_paths, self.segments, self.path_len, local_size=self.local_size)
        return PathBatch(self.segments, self.path_len, path_offset, n_paths, self.max_depth)

    def retrace(self, batch: PathBatch, paths: cl.Buffer, starts: cl.Buffer, n_list: int):
        """Re-trace the suffixes of listed paths of ``batch`` in place: path
        ``paths[k]`` (an index into the batch) from bounce ``starts[k]`` on."""
        self.launches += 1
        batch.retraced += 1
        launch(self.queue, self.k_retrace, n_list, *self.compiled.scene_args, *self._trace_args(),
               batch.path_offset, paths, starts, n_list, batch.segments, batch.path_len,
               local_size=self.local_size)
