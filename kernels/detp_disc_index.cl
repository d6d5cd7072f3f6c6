/* detp_disc_index.cl: DETP with disc indexing (García 2006; DESIGN.md 3).
 *
 * detp_disc_index  one work-item per path of a batch (global size n_paths,
 *                  any local size), which walks its segments up to the
 *                  path's end: reading only the stored segments, not every
 *                  slot, halves the cost of a pass over a session's whole
 *                  store. Each segment walks a BVH over the discs' boxes
 *                  (box_bvh.h); in every leaf it meets, it is tested against
 *                  the leaf's discs 8 at a time (float8 lanes, as detp_plain)
 *                  with DETP_TEST (detp.h), and its fixed-point power is
 *                  added to each disc it crosses with 64-bit atom_add:
 *                  work-items share discs, and integer atomics keep the sums
 *                  independent of order. Counts u = segment-disc tests (real
 *                  discs of each leaf met) and BVH nodes visited (work.h).
 *
 * Disc blocks (host: oclgi/estimators/detp_disc_index.py): the discs of a
 * leaf are stored as ceil(count / 8) blocks of 7 float8 (x, y, z, nx, ny,
 * nz, point id as int bits); padding lanes have a zero normal, which never
 * passes DETP_TEST (w.n = 0). A leaf node's `first` is its first block and
 * `count` its number of real discs.
 *
 * count_emitted = 0 skips segments leaving the light (bounce 0), as detp.cl.
 */
#include "oclgi_types.h"
#include "detp.h"
#include "work.h"
#include "box_bvh.h"

#define DISC_BLOCK 7 /* float8 per block of 8 discs */

/* One segment against the tree: every leaf it meets, 8 discs at a time. */
inline void disc_index_segment(__global const BvhNode *nodes, __global const float8 *discs,
                               __global const float4 *seg, float4 f0, float4 f1, float radius2, float ext,
                               float scale, __global long *acc, uint *visited, ulong *tests)
{
    float3 o = f0.xyz, w = f1.xyz;
    float tmax = f0.w + ext; /* exactly as detp_plain */
    float3 inv = 1.0f / w;
    long3 q = 0;
    int have_q = 0;
    BoxBvhWalk walk;
    box_bvh_start(&walk);
    int leaf;
    while ((leaf = box_bvh_next_segment(&walk, nodes, o, inv, tmax)) >= 0) {
        int count = nodes[leaf].count;
        int first = nodes[leaf].first;
        *tests += (ulong)count;
        for (int blk = first; blk < first + (count + 7) / 8; ++blk) {
            __global const float8 *b = discs + (size_t)blk * DISC_BLOCK;
            int8 hit;
            DETP_TEST(float8, hit, b[0], b[1], b[2], b[3], b[4], b[5], o.x, o.y, o.z, w.x, w.y, w.z,
                      tmax, radius2);
            if (!any(hit)) continue;
            if (!have_q) { /* quantised once per segment, as detp_plain does */
                q = convert_long3_rte(seg[2].xyz * scale);
                have_q = 1;
            }
            int ids[8], h[8];
            vstore8(as_int8(b[6]), 0, ids);
            vstore8(hit, 0, h);
            for (int k = 0; k < 8; ++k) {
                if (!h[k]) continue;
                __global long *a = acc + 3 * (size_t)ids[k];
                atom_add(a + 0, q.x);
                atom_add(a + 1, q.y);
                atom_add(a + 2, q.z);
            }
        }
    }
    *visited += walk.visited;
}

__kernel void detp_disc_index(__global const BvhNode *nodes, __global const float8 *discs,
                              __global const float4 *segments, int n_paths, int max_depth,
                              int count_emitted, float radius2, float ext, float scale,
                              __global long *acc, __global ulong *work)
{
    int p = get_global_id(0);
    if (p >= n_paths) return;
    WORK_DECL;
    uint visited = 0;
    ulong tests = 0;
    __global const float4 *path = segments + (size_t)p * max_depth * 3;
    for (int b = count_emitted ? 0 : 1; b < max_depth; ++b) {
        __global const float4 *seg = path + 3 * b;
        float4 f0 = seg[0], f1 = seg[1];
        /* The first empty slot (all zeros) ends the path; a hole (an update's
         * scratch store, update.cl) is skipped. */
        if (f1.x == 0.0f && f1.y == 0.0f && f1.z == 0.0f) {
            if (as_int(f1.w) == SEGMENT_HOLE) continue;
            break;
        }
        disc_index_segment(nodes, discs, seg, f0, f1, radius2, ext, scale, acc, &visited, &tests);
    }
    WORK_U(tests);
    WORK_NODE(visited);
    WORK_FLUSH(work);
}
