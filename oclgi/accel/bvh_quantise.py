"""The scene's wide BVH with quantised child boxes: ``BvhNode8`` records
(``bvh_wide.py``) into ``BvhNode8Q`` records (``oclgi.cl.layout``), 128
bytes instead of 224, vectorised numpy.

A node's children are placed on a grid of its own: per axis a base (the
lowest child plane, a float32) and a power-of-two step at least 1/255 of the
node's extent, and each child plane becomes a count of steps from the base
in 8 bits, as in Ylitie, Karras & Laine 2017 (compressed wide BVHs). Lower
planes are rounded down and upper planes up, so a decoded box holds its
child's exact box: the traversal's box test (``kernels/bvh.h``, the same
slab arithmetic on the decoded planes) enters every node the exact boxes
enter, possibly a few more, and finds the same nearest hit.

Why decoding is conservative in float32: ``q * step`` is exact (8-bit q, a
power-of-two step), so ``base + q * step`` rounds once, to nearest; the real
value lies below the float32 lower plane (above the upper), and rounding to
nearest never crosses a float32 (here: the plane itself). The check at the
end repeats the device's arithmetic and fails loudly if this ever did not
hold.

The nodes, their order and their children are the wide tree's; an unused
lane has child 0 (no child is node 0) and the empty box q_lo = 255,
q_hi = 0.
"""

from __future__ import annotations

import numpy as np

from ..cl.layout import BvhNode8Q

Q_MAX = 255
# Steps below this would be float32 denormals (flushed to zero on the
# device, -cl-denorms-are-zero): a flat axis takes it, every q there is 0.
MIN_STEP_EXP = -126


def _decode(base: np.ndarray, step: np.ndarray, q: np.ndarray) -> np.ndarray:
    """base + q * step in float32, as the device computes it."""
    return base[:, None] + q.astype(np.float32) * step[:, None]


def quantise(wide: np.ndarray) -> np.ndarray:
    """``BvhNode8Q`` records of ``BvhNode8`` records (same numbering)."""
    out = np.zeros(len(wide), dtype=BvhNode8Q)
    valid = np.isfinite(wide["lox"])  # unused lanes are lo = hi = +inf
    out["child"] = np.where(valid, wide["child"], 0)
    for axis, name in enumerate("xyz"):
        lo, hi = wide["lo" + name], wide["hi" + name]
        base = np.where(valid, lo, np.float32(np.inf)).min(axis=1).astype(np.float32)
        top = np.where(valid, hi, np.float32(-np.inf)).max(axis=1).astype(np.float32)
        extent = top.astype(np.float64) - base  # exact: float32 differences fit float64
        # the least power of two with 255 steps covering the extent
        _, exp = np.frexp(extent / Q_MAX)  # extent / 255 = m 2^exp, 0.5 <= m < 1
        exp = np.where(extent > 0, exp, MIN_STEP_EXP)
        exp = np.where(Q_MAX * np.ldexp(1.0, exp - 1) >= extent, exp - 1, exp)  # m == 0.5 exactly
        exp = np.maximum(exp, MIN_STEP_EXP)
        step = np.ldexp(np.float32(1.0), exp).astype(np.float32)
        rel_lo = (lo.astype(np.float64) - base[:, None]) / step[:, None]  # exact: a power-of-two divisor
        rel_hi = (hi.astype(np.float64) - base[:, None]) / step[:, None]
        q_lo = np.where(valid, np.floor(np.where(valid, rel_lo, 0.0)), Q_MAX)
        q_hi = np.where(valid, np.ceil(np.where(valid, rel_hi, 0.0)), 0)
        if (q_lo < 0).any() or (q_hi > Q_MAX).any():
            raise AssertionError("a child plane falls outside its node's 8-bit grid")
        q_lo, q_hi = q_lo.astype(np.uint8), q_hi.astype(np.uint8)
        out["base"][:, axis], out["step"][:, axis] = base, step
        out["qlo" + name], out["qhi" + name] = q_lo, q_hi
        with np.errstate(invalid="ignore"):
            inside = (_decode(base, step, q_lo) <= lo) & (_decode(base, step, q_hi) >= hi)
        if not inside[valid].all():
            raise AssertionError("a decoded child box does not hold the child's box")
    return out
