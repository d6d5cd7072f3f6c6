"""Batches of ray queries against a compiled scene's BVH (``kernels/bvh_query.cl``).

Used by tests (against brute force) and benchmarks (against Embree); the
estimators call the same traversal code (``kernels/bvh.h``) from their kernels.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.programs import launch, programs


def _rays(ctx, origins, dirs, tmax):
    n = len(origins)
    o = np.zeros((n, 4), np.float32)
    o[:, :3] = origins
    o[:, 3] = tmax
    d = np.zeros((n, 4), np.float32)
    d[:, :3] = dirs
    mf = cl.mem_flags
    return (cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=o),
            cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=d))


def closest_hits(queue, compiled, origins, dirs, tmax=np.inf, local_size=None):
    """(t, u, v, tri) for each ray: t = inf and tri = -1 on a miss."""
    ctx = queue.context
    n = len(origins)
    ob, db = _rays(ctx, origins, dirs, tmax)
    out = np.empty((n, 4), np.float32)
    hb = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, max(out.nbytes, 16))
    k = programs(ctx).get("bvh_query").bvh_query_closest
    launch(queue, k, n, *compiled.scene_args, ob, db, n, hb, local_size=local_size)
    cl.enqueue_copy(queue, out, hb)
    return out[:, 0], out[:, 1], out[:, 2], out[:, 3].view(np.int32)


def any_hits(queue, compiled, origins, dirs, tmax=np.inf, local_size=None):
    """1 for each ray that hits anything before tmax, else 0."""
    ctx = queue.context
    n = len(origins)
    ob, db = _rays(ctx, origins, dirs, tmax)
    out = np.empty(n, np.int32)
    hb = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, max(out.nbytes, 4))
    k = programs(ctx).get("bvh_query").bvh_query_any
    launch(queue, k, n, *compiled.scene_args, ob, db, n, hb, local_size=local_size)
    cl.enqueue_copy(queue, out, hb)
    return out


def traversal_work(queue, compiled, origins, dirs, tmax=np.inf, local_size=None):
    """(nodes visited, triangles tested) by each ray's closest-hit query: the
    exact work count behind rays/s, for comparing trees (the counting build
    of ``bvh_query.cl``; every other kernel traverses without counters).
    A node is a record the walk reads: a binary node (two child boxes
    tested, or a leaf's triangles) or a wide node (all of its up to 8 child
    boxes tested at once; a wide tree's leaves are lanes of their parent,
    so reaching one counts its triangles only)."""
    ctx = queue.context
    n = len(origins)
    ob, db = _rays(ctx, origins, dirs, tmax)
    out = np.empty((n, 2), np.int32)
    wb = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, max(out.nbytes, 8))
    k = programs(ctx).get("bvh_query", bvh_count=1).bvh_query_count
    launch(queue, k, n, *compiled.scene_args, ob, db, n, wb, local_size=local_size)
    cl.enqueue_copy(queue, out, wb)
    return out[:, 0], out[:, 1]
