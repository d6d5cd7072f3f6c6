"""Quantised wide nodes (oclgi/accel/bvh_quantise.py): every decoded child
box, computed in float32 as the device computes it, holds the child's exact
box and exceeds it by less than one grid step per plane; the node's
children are the wide node's; unused lanes are masked; the result is a
function of the wide tree alone. (The traversal over them is checked
against brute force and the binary walk in test_bvh_wide.py.)"""

import numpy as np
import pytest

from oclgi.accel.bvh_build import build_bvh
from oclgi.accel.bvh_quantise import Q_MAX, quantise
from oclgi.accel.bvh_wide import collapse
from oclgi.cl.layout import BvhNode8Q


def decoded(q, axis):
    """The decoded planes of every lane along one axis, float32."""
    name = "xyz"[axis]
    base = q["base"][:, axis][:, None]
    step = q["step"][:, axis][:, None]
    return (base + q["qlo" + name].astype(np.float32) * step, base + q["qhi" + name].astype(np.float32) * step)


def check(wide):
    q = quantise(wide)
    assert q.dtype == BvhNode8Q and len(q) == len(wide)
    used = np.isfinite(wide["lox"])
    assert np.array_equal(q["child"], np.where(used, wide["child"], 0))
    assert (q["child"][used] != 0).all()  # no used lane looks unused
    for axis, name in enumerate("xyz"):
        lo, hi = wide["lo" + name], wide["hi" + name]
        dlo, dhi = decoded(q, axis)
        assert dlo.dtype == np.float32
        assert (dlo[used] <= lo[used]).all() and (dhi[used] >= hi[used]).all()
        step = np.broadcast_to(q["step"][:, axis][:, None], lo.shape)
        assert (lo[used] - dlo[used] <= step[used] * 1.001).all()
        assert (dhi[used] - hi[used] <= step[used] * 1.001).all()
        # the step is a power of two, and the least that spans the node in 255 steps
        s = q["step"][:, axis]
        mant, _ = np.frexp(s)
        assert (mant == 0.5).all()
        ext = np.where(used, hi, -np.inf).max(axis=1).astype(np.float64) - np.where(used, lo, np.inf).min(axis=1)
        assert (Q_MAX * s.astype(np.float64) >= ext).all()
        small = (ext > 0) & (s > np.float32(2.0**-126))
        assert (Q_MAX * (s[small] / 2.0) < ext[small]).all()
        assert (q["qlo" + name][~used] == Q_MAX).all() and (q["qhi" + name][~used] == 0).all()
    return q


@pytest.mark.parametrize("quality", ["sah", "lbvh"])
def test_decoded_boxes_hold_the_exact_ones(rng, quality):
    # spread over magnitudes (planes far from the base, tiny and huge boxes)
    c = (rng.random((20_000, 3)) - 0.5) * np.array([1e3, 1.0, 1e-2]) + np.array([5e3, -3.0, 0.0])
    lo = c.astype(np.float32)
    hi = (c + rng.random((20_000, 3)) ** 4 * np.array([10.0, 0.01, 1e-3])).astype(np.float32)
    bvh = build_bvh(lo, hi, quality=quality)
    check(collapse(bvh.nodes).nodes)


def test_flat_and_degenerate_nodes(rng):
    """A flat axis (every box in one plane, the Cornell box's walls) and
    boxes that are points: step at the least normal float, every q exact."""
    c = rng.random((500, 3)).astype(np.float32)
    c[:, 1] = 0.25
    q = check(collapse(build_bvh(c, c, quality="sah").nodes).nodes)
    dlo, dhi = decoded(q, 1)
    used = q["child"] != 0
    assert (dlo[used] == np.float32(0.25)).all() and (dhi[used] == np.float32(0.25)).all()


def test_quantise_is_deterministic(rng):
    c = rng.random((3000, 3))
    wide = collapse(build_bvh(c, c + 0.01, quality="sah").nodes).nodes
    assert quantise(wide).tobytes() == quantise(wide.copy()).tobytes()
