"""Wide leaves as blocks of 4 triangles (oclgi/accel/bvh_leaf_blocks.py):
every leaf's run of triangles is copied, in order, into the blocks its
recoded lane points at, and nothing else is; a leaf's blocks tested 4 at a
time (kernels/geometry.h tri4_intersect) give the hit of its run tested one
triangle at a time, ties included. The traversal over them is checked bit
for bit against the binary walk in test_bvh_wide.py."""

import numpy as np
import pyopencl as cl
import pytest

from oclgi.accel.bvh_build import build_bvh
from oclgi.accel.bvh_leaf_blocks import LANES, UNIT, leaf_blocks
from oclgi.accel.bvh_wide import collapse
from oclgi.cl.layout import Tri, TriBlock4
from oclgi.cl.programs import ProgramCache


def _tris(rng, n):
    t = np.zeros(n, dtype=Tri)
    for k in range(3):
        t[f"v{k}"] = rng.random((n, 3)).astype(np.float32)
    t["id"] = rng.permutation(n)
    return t


@pytest.mark.parametrize("leaf_size", [4, 8])
def test_blocks_hold_each_leaf_in_order(rng, leaf_size):
    n = 3000
    tris = _tris(rng, n)
    c = rng.random((n, 3))
    nodes = collapse(build_bvh(c, c + 0.01, leaf_size=leaf_size, quality="sah").nodes).nodes
    out, blocks = leaf_blocks(nodes, tris)
    assert blocks.dtype == TriBlock4 and out.dtype == nodes.dtype
    used = np.isfinite(nodes["lox"])
    leaf = used & (nodes["child"] < 0)
    # inner lanes and unused lanes unchanged; every other field unchanged
    assert np.array_equal(out["child"][~leaf], nodes["child"][~leaf])
    for name in nodes.dtype.names:
        if name != "child":
            assert np.array_equal(out[name], nodes[name], equal_nan=True)
    run, code = ~nodes["child"][leaf], ~out["child"][leaf]
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


# Ray k against leaf k: its blocks by tri4_intersect, as the wide walk tests
# a leaf (kernels/bvh.h), and its run of Tri records one at a time with
# tri_intersect, as the binary walk tests a leaf; then how many of the
# run's triangles meet the ray at exactly the nearest distance (ties).
PROBE = """
#include "oclgi_types.h"
#include "geometry.h"
__kernel void leaf_probe(__global const float *rays, __global const int *leaves, __global const TriBlock4 *blocks,
                         __global const Tri *tris, __global float *out, __global int *ids)
{
    int k = get_global_id(0);
    float3 o = vload3(0, rays + 7 * k), d = vload3(0, rays + 7 * k + 3);
    float tmax = rays[7 * k + 6];
    int first = leaves[3 * k], count = leaves[3 * k + 1], b0 = leaves[3 * k + 2];
    RayShear shear = ray_shear(d);
    float bt = tmax, bu = 0.0f, bv = 0.0f;
    int bid = -1;
    for (int j = 0; j < count; j += 4) {
        __global const TriBlock4 *b = blocks + b0 + j / 4;
        float t, u, v;
        int lane = tri4_intersect(o, shear, &b->v0x, count - j, bt, &t, &u, &v);
        if (lane >= 0) {
            int4 id = b->id;
            bt = t; bu = u; bv = v;
            bid = lane == 0 ? id.x : (lane == 1 ? id.y : (lane == 2 ? id.z : id.w));
        }
    }
    float st = tmax, su = 0.0f, sv = 0.0f;
    int sid = -1;
    for (int i = first; i < first + count; ++i) {
        __global const Tri *tr = &tris[i];
        float t, u, v;
        if (tri_intersect(o, shear, vload3(0, tr->v0), vload3(0, tr->v1), vload3(0, tr->v2), st, &t, &u, &v)) {
            st = t; su = u; sv = v; sid = tr->id;
        }
    }
    int ties = 0;
    for (int i = first; i < first + count && sid >= 0; ++i) {
        __global const Tri *tr = &tris[i];
        float t, u, v;
        ties += tri_intersect(o, shear, vload3(0, tr->v0), vload3(0, tr->v1), vload3(0, tr->v2), INFINITY,
                              &t, &u, &v) && t == st;
    }
    vstore3((float3)(bt, bu, bv), 0, out + 6 * k);
    vstore3((float3)(st, su, sv), 0, out + 6 * k + 3);
    ids[3 * k] = bid;
    ids[3 * k + 1] = sid;
    ids[3 * k + 2] = ties;
}
"""


@pytest.mark.parametrize("leaf_size", [4, 8])
def test_blocks_test_a_leaf_as_its_run_bit_for_bit(cl_env, rng, leaf_size):
    """A leaf's blocks tested 4 triangles at a time give the one-at-a-time
    test's hit over its run, ties included: each lane the same arithmetic,
    and the lowest lane of equal distances kept (the one a sequential test
    keeps). The mesh is a height field (triangles sharing edges) with every
    third triangle stored twice (exact ties in one leaf), the rays aimed at
    points of a leaf's triangles, their edges and corners, some with a limit
    short of the target."""
    ctx, queue = cl_env
    g = 40
    x, z = np.meshgrid(np.arange(g + 1, dtype=np.float64), np.arange(g + 1, dtype=np.float64))
    y = rng.random((g + 1, g + 1)) * 0.7
    verts = np.stack([x, y, z], axis=-1).reshape(-1, 3) / g
    q = (np.arange(g)[:, None] * (g + 1) + np.arange(g)[None, :]).reshape(-1)
    faces = np.concatenate([np.stack([q, q + 1, q + g + 2], 1), np.stack([q, q + g + 2, q + g + 1], 1)])
    faces = np.concatenate([faces, faces[::3]])
    v = verts[faces].astype(np.float32)
    bvh = build_bvh(v.min(axis=1), v.max(axis=1), leaf_size=leaf_size, quality="sah")
    tris = np.zeros(len(v), dtype=Tri)
    for k in range(3):
        tris[f"v{k}"] = v[bvh.order, k]
    tris["id"] = bvh.order
    nodes = collapse(bvh.nodes).nodes
    out, blocks = leaf_blocks(nodes, tris)
    leaf = np.isfinite(nodes["lox"]) & (nodes["child"] < 0)
    run, code = ~nodes["child"][leaf].astype(np.int64), ~out["child"][leaf].astype(np.int64)
    first, count = run >> 3, (run & 7) + 1
    b0 = ((code >> 3) * UNIT - len(nodes) * nodes.itemsize) // TriBlock4.itemsize

    n = 200_000
    pick = rng.integers(0, len(first), n)
    target_tri = first[pick] + rng.integers(0, count[pick])
    bary = rng.dirichlet(np.ones(3), n)
    edge = rng.random(n) < 0.3  # on an edge or a corner
    bary[edge, rng.integers(0, 3, int(edge.sum()))] = 0.0
    bary /= bary.sum(axis=1, keepdims=True)
    corners = np.stack([tris[f"v{k}"][target_tri] for k in range(3)], axis=1).astype(np.float64)
    target = np.einsum("nk,nkj->nj", bary, corners)
    origins = target + rng.normal(size=(n, 3)) * 0.5 + [0.0, 1.0, 0.0]
    dirs = target - origins
    dist = np.linalg.norm(dirs, axis=1)
    dirs /= dist[:, None]
    tmax = np.where(rng.random(n) < 0.2, dist * rng.uniform(0.9, 1.1, n), np.inf)
    rays = np.concatenate([origins, dirs, tmax[:, None]], axis=1).astype(np.float32)
    leaves = np.stack([first[pick], count[pick], b0[pick]], axis=1).astype(np.int32)

    prog = cl.Program(ctx, PROBE).build(options=ProgramCache(ctx).options(()))
    mf = cl.mem_flags
    bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))
            for a in (rays, leaves, blocks, tris)]
    res, ids = np.empty((n, 6), np.float32), np.empty((n, 3), np.int32)
    res_buf, ids_buf = cl.Buffer(ctx, mf.WRITE_ONLY, res.nbytes), cl.Buffer(ctx, mf.WRITE_ONLY, ids.nbytes)
    prog.leaf_probe(queue, (n,), None, *bufs, res_buf, ids_buf)
    cl.enqueue_copy(queue, res, res_buf)
    cl.enqueue_copy(queue, ids, ids_buf)

    hit = ids[:, 1] >= 0
    assert hit.mean() > 0.7 and (~hit).any()  # the short limits cut some rays off
    assert np.array_equal(ids[:, 0], ids[:, 1])
    assert np.array_equal(res[:, 0].view(np.int32), res[:, 3].view(np.int32))
    assert np.array_equal(res[hit, 1:3].view(np.int32), res[hit, 4:6].view(np.int32))
    assert (ids[hit, 2] >= 2).mean() > 0.05  # exact ties, decided as the run decides them
