/* ray_map_knn.cl: the k nearest segments of query points (Ray Maps' k
 * nearest mode, Havran et al. 2005; host: oclgi/estimators/ray_map_knn.py).
 *
 * rmk_knn  one work-item per query point (through `order`, a permutation
 *          that only improves locality): the K nearest front-side segments
 *          under the metric, by best-first descent of a BVH over the
 *          segments' pieces, with the private max-heap of the Photon Map
 *          search (point_index.h: keys (d2, id), the K smallest kept, ties
 *          to the smaller id). The host caps the work-group size so that
 *          the group's heaps stay within PoCL's stack.
 *
 * Metrics (query x, unit normal n; segment o + t w, w unit, tmax = t_end +
 * ext; a = x - o):
 *   RMK_PLANE  t = (a.n) / (w.n), the crossing of x's tangent plane; only
 *              segments with 0 < t <= tmax are candidates (the DETP rule,
 *              detp.h, written with num = a.n: num < 0, num >= tmax wn)
 *   RMK_RAY    t = clamp(a.w, 0, tmax): the nearest point of the segment
 *   RMK_LINE   t = a.w: the nearest point of the supporting line
 * and d2 = |t w - a|^2 in float32, contraction off. Every metric keeps the
 * front-side rule w.n < -OCLGI_FRONT_COS_EPS (as DETP and Photon Maps).
 *
 * Pieces. A segment is cut into pieces along t (host); every piece keeps
 * the whole segment's o, w, tmax and its canonical id, and claims the
 * parameters [claim_lo, claim_hi): the claims of a segment's pieces
 * partition the line, so the one t of a query is claimed by exactly one
 * piece and no segment enters a heap twice. A piece's box bounds its chord,
 * padded; the chords cover the part of the line inside the host's box B_M
 * (the query points' and origins' box grown by M on every side), and a
 * point outside B_M is at least M from every query point, so
 * min(box distance, m2 = M^2 shrunk a little) bounds the d2 of every
 * piece below a node: the pruning never drops a neighbour.
 *
 * Pieces are stored as structure-of-arrays in leaf order (rows ox, oy, oz,
 * wx, wy, wz, tmax, claim_lo, claim_hi of `stride` floats, padded by
 * OCLGI_LANES entries of w = 0; ids alongside) and tested 8 at a time in
 * float8 lanes (PoCL does not vectorise loops across work-items).
 *
 * Two passes (see rmk_knn): the first within the host's guess r0.
 *
 * The result (pm_finish, point_index.h): acc = the fixed-point sum of the K-1 nearest
 * segments' powers (the K nearest with include_kth), each quantised once by
 * segment_quantise (segment.h); r2 = the K-th nearest's d2 (INFINITY when
 * fewer than K were found); with write_ids, the K neighbours' ids and d2 in
 * ascending (d2, id) order. The irradiance is photon_map.cl's pm_resolve.
 * Work counters (work.h): u = piece tests, nodes = BVH nodes visited.
 */
#include "point_index.h"

#define RMK_PLANE 0
#define RMK_RAY 1
#define RMK_LINE 2
#define RMK_ROWS 9

typedef struct {
    __global const float *ox, *oy, *oz, *wx, *wy, *wz, *tmax, *lo, *hi;
    __global const int *id;
} RmkPieces;

/* The search's bound: the K-th nearest's d2 once the heap is full, the
 * pass's guess r0sq before (INFINITY in the last pass). */
inline float rmk_bound(const PmHeap *h, float r0sq)
{
    return h->n == PM_K ? h->d2[0] : r0sq;
}

/* Offer the pieces [start, start + count) to the heap of query x (normal n). */
inline void rmk_scan(PmHeap *h, const RmkPieces *pc, int start, int count, float3 x, float3 n, int metric,
                     float r0sq)
{
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    for (int j = start; j < start + count; j += OCLGI_LANES) {
        float8 wx = vload8(0, pc->wx + j), wy = vload8(0, pc->wy + j), wz = vload8(0, pc->wz + j);
        float8 wn = wx * n.x + wy * n.y + wz * n.z;
        int8 ok = (lane < (int8)(start + count - j)) & (wn < (float8)(-OCLGI_FRONT_COS_EPS));
        if (!any(ok)) continue;
        float8 ax = x.x - vload8(0, pc->ox + j);
        float8 ay = x.y - vload8(0, pc->oy + j);
        float8 az = x.z - vload8(0, pc->oz + j);
        float8 tmax = vload8(0, pc->tmax + j);
        float8 t;
        if (metric == RMK_PLANE) {
            float8 num = ax * n.x + ay * n.y + az * n.z;
            ok &= (num < 0.0f) & (num >= tmax * wn);
            t = num / wn;
        } else {
            t = ax * wx + ay * wy + az * wz;
            if (metric == RMK_RAY) t = fmin(fmax(t, 0.0f), tmax);
        }
        ok &= (t >= vload8(0, pc->lo + j)) & (t < vload8(0, pc->hi + j));
        float8 dx = t * wx - ax, dy = t * wy - ay, dz = t * wz - az;
        float8 d2 = dx * dx + dy * dy + dz * dz;
        ok &= d2 <= (float8)(rmk_bound(h, r0sq));
        if (!any(ok)) continue;
        pm_offer_lanes(h, d2, ok, pc->id + j);
    }
}

/* The lower bound of a node: its padded box's distance, capped by m2. For
 * the plane metric, a piece claims a crossing only inside its chord, or
 * beyond B_M (at least M away): a box that does not meet x's tangent plane
 * holds no crossing nearer than M, so its bound is m2 (most of a room's
 * segments pass a wall point without crossing its plane nearby). The
 * padding, far above float32 rounding, keeps the plane test conservative. */
inline float rmk_node_bound(__global const BvhNode *nd, float3 x, float3 n, int metric, float m2)
{
    float3 lo = vload3(0, nd->lo), hi = vload3(0, nd->hi);
    if (metric == RMK_PLANE) {
        float3 c = 0.5f * (lo + hi), e = 0.5f * (hi - lo);
        float s = (c.x - x.x) * n.x + (c.y - x.y) * n.y + (c.z - x.z) * n.z;
        float r = e.x * fabs(n.x) + e.y * fabs(n.y) + e.z * fabs(n.z);
        if (fabs(s) > r) return m2;
    }
    return fmin(pm_box_dist2(lo, hi, x), m2);
}

__kernel void rmk_knn(__global const BvhNode *nodes, __global const float *soa, int stride,
                      __global const int *pid, __global const float4 *power,
                      __global const float4 *qpos, __global const float4 *qnrm,
                      __global const int *order, int n_points, int metric, float m2, float r0sq,
                      int include_kth,
                      __global long *acc, __global float *r2, int write_ids,
                      __global int *ids, __global float *d2s, __global ulong *work)
{
    int t = get_global_id(0);
    if (t >= n_points) return;
    int i = order[t];
    WORK_DECL;
    float3 x = qpos[i].xyz, n = qnrm[i].xyz;
    RmkPieces pc;
    pc.ox = soa; pc.oy = soa + stride; pc.oz = soa + 2 * stride;
    pc.wx = soa + 3 * stride; pc.wy = soa + 4 * stride; pc.wz = soa + 5 * stride;
    pc.tmax = soa + 6 * stride; pc.lo = soa + 7 * stride; pc.hi = soa + 8 * stride;
    pc.id = pid;
    PmHeap h;
    h.n = 0;
    /* Two passes: the first only looks within the host's guess r0 (a few
     * times the k-th distance of the mean density), so that the search
     * before the heap fills does not range over every box near enough to
     * an empty bound; a point that finds fewer than K there searches again
     * without it. Nothing beyond r0 is dropped from a full heap (a node or
     * segment is skipped only when its bound exceeds r0^2 >= the K-th d2),
     * so both passes give the one result. */
    int has_normal = n.x != 0.0f || n.y != 0.0f || n.z != 0.0f;
    for (int pass = 0; has_normal && pass < 2; ++pass) {
        float guess = pass == 0 ? r0sq : INFINITY;
        h.n = 0;
        int stack[OCLGI_POINT_BVH_STACK];
        float stack_d[OCLGI_POINT_BVH_STACK];
        int sp = 0, node = 0;
        for (;;) {
            __global const BvhNode *nd = &nodes[node];
            WORK_NODE(1);
            if (nd->count > 0) {
                WORK_U(nd->count);
                rmk_scan(&h, &pc, nd->first, nd->count, x, n, metric, guess);
            } else {
                int c = nd->first;
                float d0 = rmk_node_bound(&nodes[c], x, n, metric, m2);
                float d1 = rmk_node_bound(&nodes[c + 1], x, n, metric, m2);
                float b = rmk_bound(&h, guess);
                int v0 = d0 <= b, v1 = d1 <= b;
                if (v0 && v1) { /* nearer first; the other waits with its bound */
                    stack[sp] = d0 <= d1 ? c + 1 : c;
                    stack_d[sp] = fmax(d0, d1);
                    ++sp;
                    node = d0 <= d1 ? c : c + 1;
                    continue;
                }
                if (v0 || v1) { node = v0 ? c : c + 1; continue; }
            }
            float b = rmk_bound(&h, guess);
            while (sp > 0 && stack_d[sp - 1] > b) --sp;
            if (sp == 0) break;
            node = stack[--sp];
        }
        if (h.n == PM_K || guess == INFINITY) break;
    }
    pm_finish(&h, power, i, include_kth, acc, r2, write_ids, ids, d2s);
    WORK_FLUSH(work);
}
