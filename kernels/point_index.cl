/* point_index.cl: the k nearest front-side impacts of query points
 * (point_index.h), over a BVH or a hashed grid of impacts.
 *
 * pm_knn_bvh   one work-item per query point (through `order`, a
 *              permutation that only improves locality): the K nearest
 *              front-side impacts (point_index.h) by best-first descent of a
 *              BVH over the impacts (leaves hold runs of impacts in leaf
 *              order, in the structure-of-arrays `soa`: x, y, z, wx, wy, wz
 *              rows of `stride` floats, ids alongside). The host caps the
 *              work-group size so that the group's private heaps (8 K bytes
 *              per work-item) stay within PoCL's stack.
 * pm_knn_grid  the same search over a hashed uniform grid: shells of cells
 *              around the query's cell until the next shell is farther
 *              than the K-th neighbour (the measured alternative).
 *
 * Both searches end in pm_finish: acc = the fixed-point sum of the K-1
 * nearest impacts' powers (the K nearest with include_kth), each quantised
 * once by segment_quantise (segment.h) like every estimator, r2 =
 * the K-th nearest's d2; with write_ids, the K neighbours' ids and d2 in
 * ascending (d2, id) order (for tests and studies).
 * Work counters (work.h): u = impact distance tests, nodes = BVH nodes or
 * grid cells visited.
 */
#include "point_index.h"

inline int pm_has_normal(float3 n)
{
    return n.x != 0.0f || n.y != 0.0f || n.z != 0.0f;
}

inline PmImpacts pm_impacts(__global const float *soa, int stride, __global const int *ids)
{
    PmImpacts im;
    im.px = soa; im.py = soa + stride; im.pz = soa + 2 * stride;
    im.wx = soa + 3 * stride; im.wy = soa + 4 * stride; im.wz = soa + 5 * stride;
    im.id = ids;
    return im;
}

__kernel void pm_knn_bvh(__global const BvhNode *nodes, __global const float *soa, int stride,
                         __global const int *iids, __global const float4 *ipower,
                         __global const float4 *qpos, __global const float4 *qnrm,
                         __global const int *order, int n_points, int front_only, int include_kth,
                         __global long *acc, __global float *r2, int write_ids,
                         __global int *ids, __global float *d2s, __global ulong *work)
{
    int t = get_global_id(0);
    if (t >= n_points) return;
    int i = order[t];
    WORK_DECL;
    float3 q = qpos[i].xyz, n = qnrm[i].xyz;
    PmImpacts im = pm_impacts(soa, stride, iids);
    PmHeap h;
    h.n = 0;
    if (pm_has_normal(n)) {
        int stack[OCLGI_POINT_BVH_STACK];
        float stack_d[OCLGI_POINT_BVH_STACK];
        int sp = 0, node = 0;
        for (;;) {
            __global const BvhNode *nd = &nodes[node];
            WORK_NODE(1);
            if (nd->count > 0) {
                WORK_U(nd->count);
                pm_scan(&h, &im, nd->first, nd->count, q, n, front_only);
            } else {
                int c = nd->first;
                float d0 = pm_box_dist2(vload3(0, nodes[c].lo), vload3(0, nodes[c].hi), q);
                float d1 = pm_box_dist2(vload3(0, nodes[c + 1].lo), vload3(0, nodes[c + 1].hi), q);
                float b = pm_bound(&h);
                int v0 = d0 <= b, v1 = d1 <= b;
                if (v0 && v1) { /* nearer first; the other waits with its distance */
                    stack[sp] = d0 <= d1 ? c + 1 : c;
                    stack_d[sp] = fmax(d0, d1);
                    ++sp;
                    node = d0 <= d1 ? c : c + 1;
                    continue;
                }
                if (v0 || v1) { node = v0 ? c : c + 1; continue; }
            }
            float b = pm_bound(&h);
            while (sp > 0 && stack_d[sp - 1] > b) --sp;
            if (sp == 0) break;
            node = stack[--sp];
        }
    }
    pm_finish(&h, ipower, i, include_kth, acc, r2, write_ids, ids, d2s);
    WORK_FLUSH(work);
}

/* Hashed grid: cell (x, y, z) has key x | y << G | z << 2G (G =
 * OCLGI_GRID_KEY_BITS); the table (2^bits slots, linear probing,
 * OCLGI_GRID_EMPTY free) maps it to the cell's run (start, count) of
 * impacts, which are stored sorted by cell. */
inline int2 pm_grid_cell(__global const ulong *keys, __global const int2 *cells, int bits, int x,
                         int y, int z)
{
    ulong key = (ulong)x | ((ulong)y << OCLGI_GRID_KEY_BITS) | ((ulong)z << (2 * OCLGI_GRID_KEY_BITS));
    uint mask = (1u << bits) - 1u;
    uint s = (uint)((key * OCLGI_GRID_HASH_MUL) >> (64 - bits));
    for (;;) {
        ulong k = keys[s];
        if (k == key) return cells[s];
        if (k == OCLGI_GRID_EMPTY) return (int2)(0, 0);
        s = (s + 1u) & mask;
    }
}

__kernel void pm_knn_grid(__global const ulong *keys, __global const int2 *cells, int bits,
                          float4 origin_h, int4 dims, float slack,
                          __global const float *soa, int stride, __global const int *iids,
                          __global const float4 *ipower,
                          __global const float4 *qpos, __global const float4 *qnrm,
                          __global const int *order, int n_points, int front_only, int include_kth,
                          __global long *acc, __global float *r2, int write_ids,
                          __global int *ids, __global float *d2s, __global ulong *work)
{
    int t = get_global_id(0);
    if (t >= n_points) return;
    int i = order[t];
    WORK_DECL;
    float3 q = qpos[i].xyz, n = qnrm[i].xyz;
    float3 org = origin_h.xyz;
    float hs = origin_h.w;
    PmImpacts im = pm_impacts(soa, stride, iids);
    PmHeap h;
    h.n = 0;
    if (pm_has_normal(n)) {
        /* The query's cell, clamped into the grid (points outside it search
         * from the nearest cell; the stopping bound below stays valid). */
        float3 fc = clamp(floor((q - org) / hs), (float3)(0.0f), convert_float3(dims.xyz - 1));
        int3 c = convert_int3(fc);
        for (int s = 0;; ++s) {
            int x0 = max(c.x - s, 0), x1 = min(c.x + s, dims.x - 1);
            int y0 = max(c.y - s, 0), y1 = min(c.y + s, dims.y - 1);
            for (int x = x0; x <= x1; ++x) {
                for (int y = y0; y <= y1; ++y) {
                    int edge = abs(x - c.x) == s || abs(y - c.y) == s;
                    /* inside the shell's x-y frame only its two z faces are new */
                    int zstep = edge ? 1 : 2 * s;
                    for (int z = c.z - s; z <= c.z + s; z += max(zstep, 1)) {
                        if (z < 0 || z >= dims.z) continue;
                        float3 lo = org + (float3)((float)x, (float)y, (float)z) * hs;
                        float3 hi = lo + hs;
                        float b = pm_bound(&h);
                        if (b != INFINITY) {
                            float dx = fmax(fmax(lo.x - q.x, q.x - hi.x) - slack, 0.0f);
                            float dy = fmax(fmax(lo.y - q.y, q.y - hi.y) - slack, 0.0f);
                            float dz = fmax(fmax(lo.z - q.z, q.z - hi.z) - slack, 0.0f);
                            if (dx * dx + dy * dy + dz * dz > b) continue;
                        }
                        WORK_NODE(1);
                        int2 run = pm_grid_cell(keys, cells, bits, x, y, z);
                        WORK_U(run.y);
                        pm_scan(&h, &im, run.x, run.y, q, n, front_only);
                    }
                }
            }
            /* Everything unvisited lies beyond the block of cells c +- s:
             * stop when that is farther than the K-th neighbour. */
            int lx = c.x - s > 0, hx = c.x + s < dims.x - 1;
            int ly = c.y - s > 0, hy = c.y + s < dims.y - 1;
            int lz = c.z - s > 0, hz = c.z + s < dims.z - 1;
            if (!(lx || hx || ly || hy || lz || hz)) break; /* the whole grid is done */
            float b = pm_bound(&h);
            if (b != INFINITY) {
                float3 blo = org + convert_float3(c - s) * hs;
                float3 bhi = org + convert_float3(c + s + 1) * hs;
                float m = INFINITY;
                if (lx) m = fmin(m, q.x - blo.x);
                if (hx) m = fmin(m, bhi.x - q.x);
                if (ly) m = fmin(m, q.y - blo.y);
                if (hy) m = fmin(m, bhi.y - q.y);
                if (lz) m = fmin(m, q.z - blo.z);
                if (hz) m = fmin(m, bhi.z - q.z);
                m -= slack;
                if (m > 0.0f && m * m > b) break;
            }
        }
    }
    pm_finish(&h, ipower, i, include_kth, acc, r2, write_ids, ids, d2s);
    WORK_FLUSH(work);
}
