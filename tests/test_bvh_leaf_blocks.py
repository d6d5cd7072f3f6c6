"""Wide leaves as blocks of 4 triangles (oclgi/accel/bvh_leaf_blocks.py):
every leaf's run of triangles is copied, in order, into the blocks its
recoded lane points at, and nothing else is; the traversal over them is
checked bit for bit against the binary walk in test_bvh_wide.py."""

import numpy as np
import pytest

from oclgi.accel.bvh_build import build_bvh
from oclgi.accel.bvh_leaf_blocks import LANES, UNIT, leaf_blocks
from oclgi.accel.bvh_quantise import quantise
from oclgi.accel.bvh_wide import collapse
from oclgi.cl.layout import Tri, TriBlock4


def _tris(rng, n):
    t = np.zeros(n, dtype=Tri)
    for k in range(3):
        t[f"v{k}"] = rng.random((n, 3)).astype(np.float32)
    t["id"] = rng.permutation(n)
    return t


@pytest.mark.parametrize("quantised", [False, True])
@pytest.mark.parametrize("leaf_size", [4, 8])
def test_blocks_hold_each_leaf_in_order(rng, quantised, leaf_size):
    n = 3000
    tris = _tris(rng, n)
    c = rng.random((n, 3))
    wide = collapse(build_bvh(c, c + 0.01, leaf_size=leaf_size, quality="sah").nodes).nodes
    nodes = quantise(wide) if quantised else wide
    out, blocks = leaf_blocks(nodes, tris)
    assert blocks.dtype == TriBlock4 and out.dtype == nodes.dtype
    used = np.isfinite(wide["lox"])
    leaf = used & (wide["child"] < 0)
    # inner lanes and unused lanes unchanged; every other field unchanged
    assert np.array_equal(out["child"][~leaf], nodes["child"][~leaf])
    for name in nodes.dtype.names:
        if name != "child":
            assert np.array_equal(out[name], nodes[name], equal_nan=True)
    run, code = ~wide["child"][leaf], ~out["child"][leaf]
    assert np.array_equal(code & 7, run & 7)  # the count stays
    seen = np.zeros(len(blocks) * LANES, bool)
    base = len(nodes) * nodes.itemsize
    for r, k in zip(run.tolist(), code.tolist()):
        first, count = r >> 3, (r & 7) + 1
        offset = (k >> 3) * UNIT - base
        assert offset % TriBlock4.itemsize == 0
        b0 = offset // TriBlock4.itemsize
        for j in range(count):
            blk, lane = blocks[b0 + j // LANES], j % LANES
            src = tris[first + j]
            for v in range(3):
                got = [blk[f"v{v}{a}"][lane] for a in "xyz"]
                assert np.array_equal(got, src[f"v{v}"])
            assert blk["id"][lane] == src["id"]
            assert not seen[(b0 + j // LANES) * LANES + lane]
            seen[(b0 + j // LANES) * LANES + lane] = True
    assert seen.sum() == n  # every triangle once
    assert (blocks["id"].reshape(-1)[~seen] == -1).all()  # unused lanes
    assert leaf_blocks(nodes, tris)[1].tobytes() == blocks.tobytes()  # deterministic
