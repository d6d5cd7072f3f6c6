"""Point orderings along space-filling curves, computed on the device.

The sphere cache (estimators/detp_sphere_cache.py) visits query points so
that consecutive points are close: the nested spheres it keeps around the
last point then stay valid for many points (Lastra 2002b visits them in
Hilbert order; Morton/Lebesgue order is the cheaper alternative, "none" the
control).

Algorithm: the points are quantised in the cube that holds their bounding
box, ``2^bits`` cells per axis, and each gets its cell's curve key
(``kernels/ordering.cl``: Hilbert after Skilling 2004, Morton by bit
interleaving; ``3 * bits`` bits). A stable LSD radix sort of (key, index)
on the device gives the permutation: ``perm[k]`` is the index of the k-th
point along the curve, ties (points in one cell) in index order, i.e.
exactly ``numpy.argsort(keys, kind="stable")``.

========== ========= =======================================================
parameter  default   meaning
========== ========= =======================================================
method     hilbert   "hilbert", "morton" or "none" (identity permutation)
bits       10        bits per axis (1..10): 1024^3 cells, 30-bit keys
box        None      (lo, side) of the quantisation cube; None: the cube on
                     the points' bounding box (largest side)
========== ========= =======================================================

Why our own radix sort: pyopencl.algorithm.RadixSort would need ``mako``
and is slower than numpy on PoCL (DESIGN.md 6: 0.12-0.37 s for 1M 30-bit
keys against 0.08 s for numpy's stable argsort). The sort here is
``RADIX_BITS``-bit LSD with a few long sequential blocks, which suits a CPU
device. Measured (2 cores, PoCL 3.1, 30-bit Hilbert keys of uniform
points): 1M keys 7 ms on the device (14 ms with the copies from and to the
host) against 98 ms for numpy.argsort(kind="stable"); 4M keys 28 ms against
499 ms. The whole order_points of 1M points (keys and sort) takes 24 ms.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.constants import LANES, RADIX_BITS
from ..cl.programs import launch, programs
from ..errors import OclgiError
from .boxes import column_bounds

METHODS = ("hilbert", "morton", "none")
_METHOD_ID = {"hilbert": 1, "morton": 2}
MAX_BITS = 10  # keys fit 30 bits: a short sort (DESIGN.md 6: keep sort keys short)
SORT_BLOCKS = 64  # sequential blocks per pass: plenty for a few CPU cores


def _program(ctx):
    return programs(ctx).get("ordering")


def check_method(method) -> str:
    if method not in METHODS:
        raise OclgiError(f"unknown point order {method!r}; choose one of {', '.join(METHODS)}")
    return method


def _as_float4(queue, positions) -> tuple[cl.Buffer, int, np.ndarray]:
    """Device float4 copy of (n, 3) or (n, 4) positions, and their xyz on the host."""
    p = np.asarray(positions, np.float32)
    if p.ndim != 2 or p.shape[1] not in (3, 4):
        raise OclgiError(f"positions must be an (n, 3) or (n, 4) array, got shape {p.shape}")
    n = len(p)
    p4 = np.zeros((max(n, 1), 4), np.float32)
    p4[:n, :3] = p[:, :3]
    buf = cl.Buffer(queue.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=p4)
    return buf, n, p4[:n, :3]


def bounding_cube(xyz: np.ndarray) -> tuple[np.ndarray, float]:
    """(lowest corner, side) of the cube on the bounding box's low corner.

    A cube, not the box: cells stay cubic, so the curve's locality is the
    same along every axis (a flat set of points then uses one layer of cells
    rather than being stretched over all of them).
    """
    lo, hi = (b.astype(np.float64) for b in column_bounds(xyz))
    return lo, float((hi - lo).max())


def point_keys(queue, positions, method: str = "hilbert", bits: int = MAX_BITS, box=None,
               device: bool = False):
    """Curve keys (uint32, ``3 * bits`` bits) of the points, computed on the device.

    ``device=True`` returns (cl.Buffer, n) instead of a numpy array.
    """
    check_method(method)
    if method == "none":
        raise OclgiError("order 'none' has no keys")
    if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) or not 1 <= bits <= MAX_BITS:
        raise OclgiError(f"bits must be an integer in 1..{MAX_BITS}, got {bits!r}")
    buf, n, xyz = _as_float4(queue, positions)
    if box is None:
        lo, side = bounding_cube(xyz) if n else (np.zeros(3), 0.0)
    else:
        lo, side = np.asarray(box[0], np.float64), float(box[1])
    # A hair more than the side, so the farthest point still quantises to
    # the last cell (and the clamp in the kernel is only a safety net).
    inv = (1 << bits) / (side * (1 + 1e-6)) if side > 0 else 0.0
    keys = cl.Buffer(queue.context, cl.mem_flags.READ_WRITE, max(n, 1) * 4)
    k = _program(queue.context).order_keys
    launch(queue, k, -(-n // LANES), buf, n, np.array([*lo, 0.0], np.float32), inv,
           bits, _METHOD_ID[method], keys)
    if device:
        return keys, n
    out = np.empty(n, np.uint32)
    cl.enqueue_copy(queue, out, keys)
    return out


def sort_keys(queue, keys, n: int | None = None, key_bits: int = 3 * MAX_BITS, device: bool = False):
    """Stable argsort of uint32 keys below 2^key_bits, on the device.

    ``keys``: a numpy array or a cl.Buffer of ``n`` uint32 (left untouched).
    Returns the permutation as np.int32, or as a cl.Buffer with ``device=True``.
    Equals ``numpy.argsort(keys, kind="stable")`` exactly.
    """
    ctx = queue.context
    mf = cl.mem_flags
    if isinstance(keys, cl.Buffer):
        if n is None:
            raise OclgiError("sort_keys: give n with a device buffer")
        src = keys
    else:
        host = np.ascontiguousarray(keys, np.uint32)
        n = len(host)
        src = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=host if n else np.zeros(1, np.uint32))
    prog = _program(ctx)
    size = max(n, 1) * 4
    k_bufs = [cl.Buffer(ctx, mf.READ_WRITE, size) for _ in range(2)]
    v_bufs = [cl.Buffer(ctx, mf.READ_WRITE, size) for _ in range(2)]
    passes = max(1, -(-key_bits // RADIX_BITS))
    blocks = max(1, min(SORT_BLOCKS, n // 1024))
    chunk = -(-max(n, 1) // blocks)
    hist = cl.Buffer(ctx, mf.READ_WRITE, (1 << RADIX_BITS) * blocks * 4)
    # local size 1: each block is its own work-group, so the runtime spreads
    # the blocks over all cores (results do not depend on it).
    ls = 1
    k_in, v_in = src, v_bufs[1]  # v_in unused on the first pass
    for p in range(passes):
        shift = p * RADIX_BITS
        k_out, v_out = k_bufs[p % 2], v_bufs[p % 2]
        launch(queue, prog.radix_histogram, blocks, k_in, n, shift, chunk,
               blocks, hist, local_size=ls)
        launch(queue, prog.radix_scan, 1, hist, (1 << RADIX_BITS) * blocks)
        launch(queue, prog.radix_scatter, blocks, k_in, v_in, n, shift, chunk,
               blocks, hist, p == 0, k_out, v_out, local_size=ls)
        k_in, v_in = k_out, v_out
    if device:
        return v_in
    out = np.empty(n, np.int32)
    if n:
        cl.enqueue_copy(queue, out, v_in)
    return out


def order_points(queue, positions, method: str = "hilbert", bits: int = MAX_BITS, box=None,
                 device: bool = False):
    """Permutation visiting the points along the curve: ``perm[k]`` = index of the k-th point.

    np.int32 on the host, or a cl.Buffer with ``device=True``.
    """
    check_method(method)
    if method == "none":
        n = len(positions)
        perm = np.arange(n, dtype=np.int32)
        if device:
            return cl.Buffer(queue.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                             hostbuf=perm if n else np.zeros(1, np.int32))
        return perm
    keys, n = point_keys(queue, positions, method, bits, box, device=True)
    return sort_keys(queue, keys, n, 3 * bits, device=device)
