"""The disc index's 8-wide tree (oclgi/accel/box_wide.py) against the binary
tree it is collapsed from: the same leaves (block runs and counts), each
once; every lane box a binary node's box bit for bit and every leaf's wide
ancestors among its binary ones (what makes the wide walk cull no more
than the binary one, kernels/box_wide.h); unused lanes masked; the stack
the walk writes within its bound, counted by a host walk that pushes every
child, as the device does.
"""

import numpy as np
import pytest

from oclgi.accel.box_wide import MAX_LEAF, collapse_boxes
from oclgi.accel.boxes import leaf_blocks
from oclgi.accel.bvh_build import build_bvh
from oclgi.cl.constants import BOX_LEAF_BITS, BOX_WIDE_STACK
from oclgi.cl.layout import WIDE
from oclgi.errors import OclgiError


def _tree(rng, n, leaf_size):
    lo = rng.random((n, 3)).astype(np.float32)
    hi = lo + rng.random((n, 3)).astype(np.float32) * 0.05
    nodes, _blk, _lane, _n_blocks = leaf_blocks(build_bvh(lo, hi, leaf_size).nodes, n)
    return nodes


def _binary_ancestors(nodes):
    """Each binary node's set of ancestors (root first)."""
    anc = {0: ()}
    stack = [0]
    while stack:
        i = stack.pop()
        if nodes["count"][i] == 0:
            for c in (nodes["first"][i], nodes["first"][i] + 1):
                anc[int(c)] = anc[i] + (i,)
                stack.append(int(c))
    return anc


def _lane_box(rec, k):
    return (np.array([rec["lox"][k], rec["loy"][k], rec["loz"][k]]),
            np.array([rec["hix"][k], rec["hiy"][k], rec["hiz"][k]]))


@pytest.mark.parametrize("n, leaf_size", [(1, 32), (20, 32), (5000, 1), (5000, 8), (20000, 32)])
def test_wide_tree_holds_the_binary_leaves_and_boxes(rng, n, leaf_size):
    nodes = _tree(rng, n, leaf_size)
    wide = collapse_boxes(nodes, "discs")
    recs = wide.nodes
    box = lambda i: (nodes["lo"][i].tobytes(), nodes["hi"][i].tobytes())  # noqa: E731
    all_boxes = {box(i) for i in range(len(nodes))}
    leaf_of_block = {int(nodes["first"][i]): i for i in np.nonzero(nodes["count"] > 0)[0]}
    anc = _binary_ancestors(nodes)
    leaves, visits = [], 0
    # Host walk as the device's: every used child pushed; the boxes of the
    # lanes that led to each entry kept with it.
    stack = [(0, ())]
    while stack:
        c, above = stack.pop()
        if c < 0:
            x = ~c
            first, count = x >> BOX_LEAF_BITS, (x & (MAX_LEAF - 1)) + 1
            b = leaf_of_block[first]
            assert nodes["count"][b] == count
            assert above[-1] == box(b)  # the leaf's own box, then its wide ancestors':
            assert set(above[:-1]) <= {box(i) for i in anc[b]}  # boxes of its binary ancestors
            leaves.append(b)
            continue
        visits += 1
        rec = recs[c]
        assert len(stack) + WIDE <= wide.stack_need <= BOX_WIDE_STACK  # the 8 writes fit
        for k in range(WIDE):
            ch = int(rec["child"][k])
            lo, hi = _lane_box(rec, k)
            if ch == 0:
                assert np.all(lo == np.inf) and np.all(hi == np.inf)
                continue
            lane_box = (lo.astype(np.float32).tobytes(), hi.astype(np.float32).tobytes())
            assert lane_box in all_boxes
            stack.append((ch, above + (lane_box,)))
    binary_leaves = np.nonzero(nodes["count"] > 0)[0]
    assert sorted(leaves) == sorted(binary_leaves.tolist())  # each leaf once
    assert visits == len(recs)  # every node reached
    assert wide.depth <= max(len(a) for a in anc.values()) + 1  # no deeper than the binary tree
    if len(binary_leaves) > 64:
        assert len(recs) < 0.6 * (len(nodes) - len(binary_leaves))  # fewer nodes than binary inner ones


def test_too_large_leaves_are_refused(rng):
    nodes = _tree(rng, MAX_LEAF + 1, MAX_LEAF + 1)  # one leaf of 257
    with pytest.raises(OclgiError, match="leaf_size"):
        collapse_boxes(nodes, "discs")
