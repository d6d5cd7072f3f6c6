"""Batches of ray queries against a compiled scene's BVH (``kernels/bvh_query.cl``).

Used by tests (against brute force) and benchmarks (against Embree); the
estimators call the same traversal code (``kernels/bvh.h``) from their kernels.

The caller's arrays are the kernels' buffers (``CL_MEM_USE_HOST_PTR``): on
a CPU device nothing is packed or copied on the way in or out. Packing the
rays into float4s and copying them took 45 ms per 10^6 rays, a third of an
incoherent query of the bunny; a query of 10^6 rays that all miss now takes
5 ms, its kernel 4.8.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.programs import launch, programs
from ..errors import OclgiError


def _rows(a, shape) -> np.ndarray:
    """``a`` as a C-contiguous float32 array of ``shape``: itself when it
    already is one (read in place, whatever its alignment: a kernel reads
    it as floats), else a copy."""
    a = np.ascontiguousarray(a, dtype=np.float32)
    if a.shape != shape:
        raise OclgiError(f"rays: expected an array of shape {shape}, got {a.shape}")
    return a


def _empty(dtype, shape, align: int) -> np.ndarray:
    """An uninitialised array whose data starts on an ``align``-byte boundary."""
    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    raw = np.empty(max(nbytes, 1) + align, np.uint8)
    skip = -raw.ctypes.data % align
    return raw[skip:skip + nbytes].view(dtype).reshape(shape)


class _Rays:
    """The caller's rays as device buffers over their own memory
    (USE_HOST_PTR: on a CPU device the kernels read the numpy arrays in
    place, with no packing or copy; a GPU driver copies them). The arrays
    must outlive the query, so they are kept here."""

    def __init__(self, queue, origins, dirs, tmax):
        self.queue = queue
        # outputs start where the device would place a buffer of its own
        self.align = max(queue.device.mem_base_addr_align // 8, 64)
        n = len(origins)
        self.n = n
        self.origins = _rows(origins, (n, 3))
        self.dirs = _rows(dirs, (n, 3))
        tmax = np.asarray(tmax, np.float32)
        # one limit for every ray: a one-element array read with step 0
        self.step = 0 if tmax.ndim == 0 else 1
        self.tmax = _rows(tmax.reshape(-1), (1 if tmax.ndim == 0 else n,))
        self.args = () if n == 0 else \
            tuple(self.wrap(a, cl.mem_flags.READ_ONLY) for a in (self.origins, self.dirs, self.tmax)) + \
            (np.int32(self.step),)

    def wrap(self, a: np.ndarray, flags) -> cl.Buffer:
        return cl.Buffer(self.queue.context, flags | cl.mem_flags.USE_HOST_PTR, hostbuf=a)

    def run(self, kernel, compiled, dtype, shape, local_size) -> np.ndarray:
        """Launch ``kernel`` over the rays into a new array of ``dtype`` and
        ``shape`` (written in place where the device can), and return it."""
        out = _empty(dtype, shape, self.align)
        if self.n == 0:
            return out
        buf = self.wrap(out, cl.mem_flags.WRITE_ONLY)
        launch(self.queue, kernel, self.n, *compiled.scene_args, *self.args, self.n, buf, local_size=local_size)
        # Mapping a USE_HOST_PTR buffer brings its contents to ``out`` (a
        # no-op where the device wrote there itself).
        mapped, _ = cl.enqueue_map_buffer(self.queue, buf, cl.map_flags.READ, 0, shape, dtype, is_blocking=True)
        mapped.base.release()
        return out


def closest_hits(queue, compiled, origins, dirs, tmax=np.inf, local_size=None, defines=None):
    """(t, u, v, tri) for each ray: t = inf and tri = -1 on a miss.
    ``defines``: the query program's own build defines (a test's or a
    benchmark's variant of kernels/bvh.h, e.g. ``scene_flat_instances``)."""
    rays = _Rays(queue, origins, dirs, tmax)
    k = programs(queue.context).get("bvh_query", **(defines or {})).bvh_query_closest
    out = rays.run(k, compiled, np.float32, (rays.n, 4), local_size)
    return out[:, 0], out[:, 1], out[:, 2], out[:, 3].view(np.int32)


def any_hits(queue, compiled, origins, dirs, tmax=np.inf, local_size=None, defines=None):
    """1 for each ray that hits anything before tmax, else 0 (``defines``: as closest_hits')."""
    rays = _Rays(queue, origins, dirs, tmax)
    k = programs(queue.context).get("bvh_query", **(defines or {})).bvh_query_any
    return rays.run(k, compiled, np.int32, (rays.n,), local_size)


def traversal_work(queue, compiled, origins, dirs, tmax=np.inf, local_size=None):
    """(nodes visited, triangles tested) by each ray's closest-hit query: the
    exact work count behind rays/s, for comparing trees (the counting build
    of ``bvh_query.cl``; every other kernel traverses without counters).
    A node is a record the walk reads: a binary node (two child boxes
    tested, or a leaf's triangles) or a wide node (all of its up to 8 child
    boxes tested at once; a wide tree's leaves are lanes of their parent,
    so reaching one counts its triangles only)."""
    rays = _Rays(queue, origins, dirs, tmax)
    k = programs(queue.context).get("bvh_query", bvh_count=1).bvh_query_count
    out = rays.run(k, compiled, np.int32, (rays.n, 2), local_size)
    return out[:, 0], out[:, 1]
