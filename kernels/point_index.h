/* point_index.h: the k-nearest-neighbour search of the Photon Map estimator.
 *
 * Neighbour order. Impacts are ranked by the key (d2, id): d2 the squared
 * distance to the query point, computed as ((dx*dx + dy*dy) + dz*dz) in
 * float32 with contraction off (so numpy float32 reproduces it bit for bit),
 * id the impact's canonical index (its rank in (path, bounce) order over the
 * whole run). The neighbour set is the K smallest keys: equal distances are
 * broken by the smaller id, so the set does not depend on traversal order
 * or work-group size, and a brute-force reference finds the same.
 *
 * The K best keys live in a bounded max-heap in private memory (arrays of K
 * floats and ints): an impact enters while the heap has room, then only if
 * its key is smaller than the top's, replacing it. The top is the K-th
 * nearest once the heap is full, and its d2 bounds the search: a box
 * whose (conservative) distance exceeds it cannot hold a better key; a box at
 * exactly that distance may hold an equal d2 with a smaller id, so it is
 * still visited.
 *
 * Front side: with front_only, an impact counts only when its direction w
 * arrives on the query normal's side, w.n < -OCLGI_FRONT_COS_EPS (the same
 * rule as DETP's): light on the other side of a thin wall is not this surface's.
 * A zero normal (a camera ray that missed) finds nothing.
 *
 * OCLGI_KNN_K (build define) is K; the host builds one program per K
 * (oclgi/accel/point_index.py). The default below only serves a build of
 * the file on its own; tests/test_constants.py keeps it equal to
 * oclgi/estimators/photon_map.py's DEFAULT_K.
 */
#ifndef OCLGI_POINT_INDEX_H
#define OCLGI_POINT_INDEX_H

#pragma OPENCL FP_CONTRACT OFF

#include "oclgi_types.h"
#include "segment.h"
#include "work.h"

#ifndef OCLGI_KNN_K
#define OCLGI_KNN_K 50
#endif
#define PM_K OCLGI_KNN_K

/* (da, ia) < (db, ib) in the neighbour order */
#define PM_LESS(da, ia, db, ib) ((da) < (db) || ((da) == (db) && (ia) < (ib)))

typedef struct {
    float d2[PM_K];
    int id[PM_K];
    int n;
} PmHeap;

inline float pm_dist2(float3 p, float3 q)
{
    float dx = p.x - q.x, dy = p.y - q.y, dz = p.z - q.z;
    return dx * dx + dy * dy + dz * dz;
}

/* Does direction w arrive on normal n's front side? Products summed in the
 * order pm_scan's lanes sum them, so the answers agree. */
inline int pm_arrives_front(float3 w, float3 n)
{
    return w.x * n.x + w.y * n.y + w.z * n.z < -OCLGI_FRONT_COS_EPS;
}

/* Squared distance from q to a box; never larger than pm_dist2 of a point in
 * it: each clamped difference is a rounded subtraction of a box bound, which
 * rounds no further from q than the point's coordinate (rounding is
 * monotone), and the squares and sums are taken in the same order. */
inline float pm_box_dist2(float3 lo, float3 hi, float3 q)
{
    float dx = fmax(fmax(lo.x - q.x, q.x - hi.x), 0.0f);
    float dy = fmax(fmax(lo.y - q.y, q.y - hi.y), 0.0f);
    float dz = fmax(fmax(lo.z - q.z, q.z - hi.z), 0.0f);
    return dx * dx + dy * dy + dz * dz;
}

/* Current bound: nothing whose d2 exceeds it can enter the heap. */
inline float pm_bound(const PmHeap *h)
{
    return h->n == PM_K ? h->d2[0] : INFINITY;
}

inline void pm_offer(PmHeap *h, float d, int id)
{
    if (h->n < PM_K) { /* sift up from the new leaf */
        int c = h->n++;
        while (c > 0) {
            int p = (c - 1) >> 1;
            if (!PM_LESS(h->d2[p], h->id[p], d, id)) break;
            h->d2[c] = h->d2[p]; h->id[c] = h->id[p];
            c = p;
        }
        h->d2[c] = d; h->id[c] = id;
        return;
    }
    if (!PM_LESS(d, id, h->d2[0], h->id[0])) return;
    int c = 0; /* replace the top, sift down */
    for (;;) {
        int l = 2 * c + 1;
        if (l >= PM_K) break;
        int r = l + 1;
        int m = (r < PM_K && PM_LESS(h->d2[l], h->id[l], h->d2[r], h->id[r])) ? r : l;
        if (!PM_LESS(d, id, h->d2[m], h->id[m])) break;
        h->d2[c] = h->d2[m]; h->id[c] = h->id[m];
        c = m;
    }
    h->d2[c] = d; h->id[c] = id;
}

/* Offer the lanes of a block that pass ``ok`` to the heap, lane order. */
inline void pm_offer_lanes(PmHeap *h, float8 d2, int8 ok, __global const int *ids)
{
    float d[OCLGI_LANES];
    int m[OCLGI_LANES];
    vstore8(d2, 0, d);
    vstore8(ok, 0, m);
    for (int l = 0; l < OCLGI_LANES; ++l)
        if (m[l]) pm_offer(h, d[l], ids[l]);
}

/* Impacts are stored as structure-of-arrays (px, py, pz, wx, wy, wz, id,
 * each padded with OCLGI_LANES entries past the end) so that a run of them
 * is tested OCLGI_LANES at a time in vector lanes: PoCL does not vectorise
 * loops across work-items, so explicit lanes are where the speed is. Lane
 * arithmetic is IEEE per lane, bit for bit the scalar pm_dist2. */
typedef struct {
    __global const float *px, *py, *pz; /* position */
    __global const float *wx, *wy, *wz; /* arriving direction */
    __global const int *id;             /* canonical id */
} PmImpacts;

/* Offer the impacts [start, start + count) to the heap of query q (normal n). */
inline void pm_scan(PmHeap *h, const PmImpacts *im, int start, int count, float3 q, float3 n,
                    int front_only)
{
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    for (int j = start; j < start + count; j += OCLGI_LANES) {
        float8 dx = vload8(0, im->px + j) - q.x;
        float8 dy = vload8(0, im->py + j) - q.y;
        float8 dz = vload8(0, im->pz + j) - q.z;
        float8 d2 = dx * dx + dy * dy + dz * dz;
        int8 ok = (lane < (int8)(start + count - j)) & (d2 <= (float8)(pm_bound(h)));
        if (front_only) {
            float8 wn = vload8(0, im->wx + j) * n.x + vload8(0, im->wy + j) * n.y
                      + vload8(0, im->wz + j) * n.z;
            ok &= wn < (float8)(-OCLGI_FRONT_COS_EPS);
        }
        if (!any(ok)) continue;
        pm_offer_lanes(h, d2, ok, im->id + j);
    }
}

/* Heap sort in place: ascending (d2, id). */
inline void pm_sort(PmHeap *h)
{
    for (int end = h->n - 1; end > 0; --end) {
        float d = h->d2[end]; int id = h->id[end];
        h->d2[end] = h->d2[0]; h->id[end] = h->id[0];
        int c = 0;
        for (;;) {
            int l = 2 * c + 1;
            if (l >= end) break;
            int r = l + 1;
            int m = (r < end && PM_LESS(h->d2[l], h->id[l], h->d2[r], h->id[r])) ? r : l;
            if (!PM_LESS(d, id, h->d2[m], h->id[m])) break;
            h->d2[c] = h->d2[m]; h->id[c] = h->id[m];
            c = m;
        }
        h->d2[c] = d; h->id[c] = id;
    }
}

/* The end of a k-nearest search: acc = the fixed-point sum of the K-1 (or,
 * with include_kth, the K) nearest powers, r2 = the K-th distance squared
 * (INFINITY when fewer than K were found); with write_ids the neighbours in
 * ascending (d2, id) order too. Photon Maps (point_index.cl) and Ray Maps'
 * k-nearest rays (ray_map_knn.cl) share it. */
inline void pm_finish(PmHeap *h, __global const float4 *power, int i, int include_kth,
                      __global long *acc, __global float *r2, int write_ids,
                      __global int *ids, __global float *d2s)
{
    long3 s = (long3)(0);
    float r = INFINITY;
    if (h->n == PM_K) {
        r = h->d2[0];
        /* heap slot 0 is the K-th nearest: the K-1 estimator leaves it out */
        for (int j = include_kth ? 0 : 1; j < PM_K; ++j)
            s += segment_quantise(power[h->id[j]].xyz);
    }
    acc[3 * i + 0] = s.x;
    acc[3 * i + 1] = s.y;
    acc[3 * i + 2] = s.z;
    r2[i] = r;
    if (write_ids) {
        pm_sort(h);
        for (int j = 0; j < PM_K; ++j) {
            ids[(size_t)i * PM_K + j] = j < h->n ? h->id[j] : -1;
            d2s[(size_t)i * PM_K + j] = j < h->n ? h->d2[j] : INFINITY;
        }
    }
}

#endif
