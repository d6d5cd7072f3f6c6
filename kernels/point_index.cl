/* point_index.cl: the k nearest front-side impacts of query points
 * (point_index.h), over a BVH of impacts.
 *
 * pm_knn_bvh   one work-item per query point (through `order`, a
 *              permutation that only improves locality): the K nearest
 *              front-side impacts (point_index.h) by best-first descent of a
 *              BVH over the impacts (leaves hold runs of impacts in leaf
 *              order, in the structure-of-arrays `soa`: x, y, z, wx, wy, wz
 *              rows of `stride` floats, ids alongside). The host caps the
 *              work-group size so that the group's private heaps (8 K bytes
 *              per work-item) stay within PoCL's stack.
 *
 * The search ends in pm_finish: acc = the fixed-point sum of the K-1
 * nearest impacts' powers (the K nearest with include_kth), each quantised
 * once by segment_quantise (segment.h) like every estimator, r2 =
 * the K-th nearest's d2; with write_ids, the K neighbours' ids and d2 in
 * ascending (d2, id) order (for tests and studies).
 * Work counters (work.h): u = impact distance tests, nodes = BVH nodes
 * visited.
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
