"""Point orderings (oclgi/accel/ordering.py, kernels/ordering.cl).

The Hilbert keys must be a true Hilbert curve: over a whole grid the
key -> cell map is a bijection and consecutive keys are face-adjacent cells;
they must also be Skilling's curve (the numpy decoder below inverts them),
including at the 10 bits per axis the estimator uses. Morton keys must equal
a plain bit interleave, and the device radix sort must equal numpy's stable
argsort exactly.
"""

import numpy as np
import pyopencl as cl
import pytest

from oclgi.accel import ordering
from oclgi.errors import OclgiError


@pytest.fixture(scope="module")
def queue(cl_env):
    return cl_env[1]


def hilbert_decode(keys, bits):
    """Skilling's TransposetoAxes (2004), integers in numpy: key -> (x, y, z) cells."""
    keys = np.asarray(keys, np.int64)
    X = [np.zeros_like(keys) for _ in range(3)]
    for q in range(bits):  # key bits x_q y_q z_q, most significant first within each triple
        for i in range(3):
            X[i] |= ((keys >> (3 * q + 2 - i)) & 1) << q
    t = X[2] >> 1  # Gray decode
    X[2] ^= X[1]
    X[1] ^= X[0]
    X[0] ^= t
    q = 2
    while q != 1 << bits:  # undo excess work
        p = q - 1
        for i in (2, 1, 0):
            m = (X[i] & q) != 0
            x0 = X[0].copy()
            t = (x0 ^ X[i]) & p
            X[0] = np.where(m, x0 ^ p, x0 ^ t)
            if i:
                X[i] = np.where(m, X[i], X[i] ^ t)
        q <<= 1
    return np.stack(X, axis=1)


def morton_reference(cells, bits):
    key = np.zeros(len(cells), np.int64)
    for q in range(bits - 1, -1, -1):
        for i in range(3):
            key = (key << 1) | ((cells[:, i].astype(np.int64) >> q) & 1)
    return key


def grid_points(bits):
    """Cell centres of a 2^bits grid in the box (0, 2^bits): quantise to their own cells."""
    side = 1 << bits
    cells = np.indices((side, side, side)).reshape(3, -1).T
    return cells, (cells + 0.5).astype(np.float32), (np.zeros(3), float(side))


@pytest.mark.parametrize("bits", [4, 5])
def test_hilbert_is_a_hilbert_curve_over_a_whole_grid(queue, bits):
    cells, pts, box = grid_points(bits)  # 2^12 and 2^15 cells
    keys = ordering.point_keys(queue, pts, "hilbert", bits=bits, box=box).astype(np.int64)
    # bijection: every key of the grid exactly once
    assert np.array_equal(np.sort(keys), np.arange(len(cells)))
    # consecutive keys are face-adjacent cells
    walk = cells[np.argsort(keys)]
    step = np.abs(np.diff(walk, axis=0)).sum(axis=1)
    assert (step == 1).all(), f"{int((step != 1).sum())} jumps"
    # and it is Skilling's curve: the reference decoder inverts the keys
    assert np.array_equal(hilbert_decode(keys, bits), cells) and walk[0].tolist() == [0, 0, 0]


def test_hilbert_at_ten_bits(queue, rng):
    """The production resolution: random runs of consecutive 30-bit keys decode to a
    face-adjacent walk, and the device encodes those cells back to the same keys."""
    keys = np.concatenate([np.arange(s, s + 2000) for s in rng.integers(0, 2**30 - 2000, size=8)])
    cells = hilbert_decode(keys, 10)
    assert (np.abs(np.diff(cells.reshape(8, 2000, 3), axis=1)).sum(axis=2) == 1).all()
    back = ordering.point_keys(queue, (cells + 0.5).astype(np.float32), "hilbert", bits=10, box=(np.zeros(3), 1024.0))
    assert np.array_equal(back.astype(np.int64), keys)


def test_morton_equals_bit_interleave(queue, rng):
    cells, pts, box = grid_points(4)
    keys = ordering.point_keys(queue, pts, "morton", bits=4, box=box)
    assert np.array_equal(keys.astype(np.int64), morton_reference(cells, 4))
    cells = rng.integers(0, 1024, size=(50_000, 3))
    keys = ordering.point_keys(queue, (cells + 0.5).astype(np.float32), "morton", bits=10, box=(np.zeros(3), 1024.0))
    assert np.array_equal(keys.astype(np.int64), morton_reference(cells, 10))


def test_quantisation_uses_the_bounding_cube(queue, rng):
    """Default box: the cube on the points' bounding box; its far corner is the last cell."""
    pts = (rng.random((1000, 3)) * [3.0, 1.0, 0.5] + [-1, 2, 5]).astype(np.float32)
    pts[0] = pts.max(axis=0)
    pts[1] = pts.min(axis=0)
    keys = ordering.point_keys(queue, pts, "morton", bits=10)
    lo = pts.min(axis=0).astype(np.float64)
    side = float((pts.max(axis=0) - lo).max())
    cells = np.clip(np.floor((pts - lo) * (1024 / (side * (1 + 1e-6)))), 0, 1023).astype(np.int64)
    # float32 rounding in the kernel may move a point sitting on a cell border
    assert (keys.astype(np.int64) == morton_reference(cells, 10)).mean() > 0.999
    assert keys[1] == 0  # the low corner: cell (0, 0, 0)
    far = hilbert_decode(ordering.point_keys(queue, pts[:1], "hilbert", bits=10, box=(lo, side)), 10)[0]
    assert far[0] == 1023  # the longest axis spans all cells, the far corner is the last one
    # one point, or all points equal: a zero-size cube, every key 0
    assert ordering.point_keys(queue, np.ones((5, 3), np.float32), "hilbert").tolist() == [0] * 5


@pytest.mark.parametrize("n, high", [(0, 1), (1, 1), (1000, 7), (100_003, 1000), (300_000, 2**30)])
def test_device_sort_equals_numpy_stable_argsort(queue, rng, n, high):
    """Exactly argsort(kind="stable"): many ties (high = 7, 1000) check stability."""
    keys = rng.integers(0, high, size=n).astype(np.uint32)
    perm = ordering.sort_keys(queue, keys, key_bits=30)
    assert perm.dtype == np.int32 and np.array_equal(perm, np.argsort(keys, kind="stable"))


def test_order_points(queue, rng):
    pts = rng.random((20_000, 4)).astype(np.float32)  # (n, 4) like QueryPoints.positions
    for method in ("hilbert", "morton"):
        keys = ordering.point_keys(queue, pts, method)
        perm = ordering.order_points(queue, pts, method)
        assert np.array_equal(perm, np.argsort(keys, kind="stable"))
        # the ordering is local: consecutive points are far closer than random pairs
        gap = np.linalg.norm(np.diff(pts[perm, :3], axis=0), axis=1).mean()
        assert gap < 0.1 * np.linalg.norm(np.diff(pts[:, :3], axis=0), axis=1).mean()
    assert np.array_equal(ordering.order_points(queue, pts, "none"), np.arange(20_000))
    buf = ordering.order_points(queue, pts, "hilbert", device=True)
    out = np.empty(20_000, np.int32)
    cl.enqueue_copy(queue, out, buf)
    assert np.array_equal(out, ordering.order_points(queue, pts, "hilbert"))


def test_bad_input(queue):
    with pytest.raises(OclgiError, match="unknown point order"):
        ordering.order_points(queue, np.zeros((3, 3), np.float32), "peano")
    with pytest.raises(OclgiError, match="bits"):
        ordering.point_keys(queue, np.zeros((3, 3), np.float32), "hilbert", bits=11)
    with pytest.raises(OclgiError, match="positions"):
        ordering.point_keys(queue, np.zeros((3, 2), np.float32), "hilbert")
