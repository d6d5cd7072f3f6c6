/* detp_sphere_cache.cl: DETP with a sphere cache (Lastra 2002b; DESIGN.md 3).
 *
 * Entry points and work sizes:
 *   sc_gather  one work-item per paths_per_item paths of a batch: tests
 *              every segment against the root sphere S_0 (it holds every
 *              disc) and appends the record of each one that meets it to
 *              list 0 (rec0, slot0; order immaterial: sums are integers).
 *              Counts t.
 *   sc_runs    one work-item per run (run_length consecutive query points
 *              of the curve order perm[]), launched in waves of as many runs
 *              as the scratch memory holds. A work-item keeps a stack of
 *              spheres S_1 ... S_L (radii[k]; centres in private memory) and
 *              their segment lists, copies of records, in its own slice of
 *              the scratch (cap entries). Per point x: find the deepest j
 *              such that S_1..S_j all still hold the whole disc
 *              (|x - c_k| + d <= R_k), re-centre S_j+1..S_L on x, rebuild
 *              each list from its parent's, then DETP_TEST (detp.h) the
 *              innermost list and add the fixed-point powers to the point's
 *              sums. Counts t (one per parent entry tested) and u (one per
 *              innermost entry).
 *
 * Exactness. Every variant selects segments with DETP_TEST, on the same
 * floats (records hold o, w and tmax = t_end + ext as detp.cl computes it),
 * so the only way to differ from plain DETP is to miss a crossing segment
 * from the innermost list. A segment DETP_TEST accepts passes, up to
 * rounding, within d of x at a parameter in (0, tmax] of its line; every
 * sphere of the stack holds the disc (the prefix rule above, not merely the
 * deepest sphere that holds it: the spheres are re-centred at different
 * points and are not truly nested), so the segment meets every sphere of
 * the stack. The segment-sphere test is made conservative by SC_MU: it
 * accepts a distance up to R + SC_MU (|c - o|_1 + R), at least 100 times
 * the rounding of either test (a few ulps of |c - o| + R). Over-accepting
 * costs a few tests; under-accepting would lose power.
 *
 * Overflow. Lists grow on the run's stack: list k follows list k-1. When a
 * rebuild would pass `cap`, the work-item stops before that point (nothing
 * of the point is added), records how far its run got (run_done), raises
 * status[0] and the size it needed at least (status[1]). The host reruns
 * the unfinished runs with a larger cap, or, past its memory budget, on
 * each half of list 0 in turn (`first`, n0 select the piece). A resumed run
 * first replays the sphere centres of its earlier points (containment
 * tests only) and rebuilds those lists uncounted, so sums and counts equal
 * a run that never overflowed. status[2] is the largest stack used, to
 * size the next batch.
 *
 * Sums: per point, private 64-bit sums of segment_fixed_power (segment.h),
 * exactly as detp.cl, added once to the point's acc (a point belongs to
 * one run, so plain adds).
 */
#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "work.h"
#include "detp_resolve.h"
#include "lane_bits.h"

/* OCLGI_SC_MAX_LEVELS and OCLGI_SC_MU: oclgi/cl/constants.py. */
#define SC_MU ((float)OCLGI_SC_MU)
#define SC_GATHER_BUF 32 /* list0 records a gather work-item buffers per atomic */

/* A segment record (ScRecord, oclgi_types.h), 2 float4: (o, tmax) and
   (w, 1 / |w|^2), tmax = t_end + ext computed as detp.cl does (INFINITY
   when the segment escapes), o and w the stored floats: DETP_TEST reads the
   record and sees exactly what detp.cl sees. The segment's slot in the batch (for its power, read only
   on a hit) is kept in a parallel int array, not in a float lane: small
   integers read as floats are denormals, the compiler does this arithmetic
   on whole float4s, and denormal operands made every test ~20 times slower
   (measured on PoCL 3.1; -cl-denorms-are-zero also cures it).

   Segment-sphere test: the closest point of the segment to c is at
   s = clamp((c - o).w / |w|^2, 0, tmax); conservative by SC_MU (header). */
inline int sc_meets(float cx, float cy, float cz, float r, float4 a, float4 b)
{
    float vx = cx - a.x, vy = cy - a.y, vz = cz - a.z;
    float s = fmin(fmax((vx * b.x + vy * b.y + vz * b.z) * b.w, 0.0f), a.w);
    float ex = vx - s * b.x, ey = vy - s * b.y, ez = vz - s * b.z;
    /* |v|_1 >= |v|: a slack at least SC_MU (|c - o| + r), without a sqrt */
    float lim = r + SC_MU * (fabs(vx) + fabs(vy) + fabs(vz) + r);
    return ex * ex + ey * ey + ez * ez <= lim * lim;
}

inline void sc_flush(__global ScRecord *rec0, __global int *slot0, volatile __global int *n0,
                     const ScRecord *buf, const int *slots, int nb)
{
    int at = atomic_add(n0, nb);
    for (int k = 0; k < nb; ++k) rec0[(size_t)at + k] = buf[k];
    for (int k = 0; k < nb; ++k) slot0[at + k] = slots[k];
}

__kernel void sc_gather(__global const Segment *segments, int n_paths, int max_depth, int count_emitted,
                        int paths_per_item, float4 c0, float r0, float ext,
                        __global ScRecord *rec0, __global int *slot0, volatile __global int *n0,
                        __global ulong *work)
{
    int p0 = get_global_id(0) * paths_per_item;
    if (p0 >= n_paths) return;
    WORK_DECL;
    ScRecord buf[SC_GATHER_BUF];
    int slots[SC_GATHER_BUF];
    int nb = 0;
    int p1 = min(n_paths, p0 + paths_per_item);
    for (int p = p0; p < p1; ++p) {
        for (int b = segment_first(count_emitted); b < max_depth; ++b) {
            int slot = p * max_depth + b;
            SegmentView s;
            if (!segment_read(segments + (size_t)slot, &s)) {
                if (segment_is_hole(segments + (size_t)slot)) continue;
                break; /* the path's end */
            }
            float tmax = s.t_end + ext; /* as detp.cl */
            float4 a = (float4)(s.o, tmax);
            float4 w = (float4)(s.w, 1.0f / (s.w.x * s.w.x + s.w.y * s.w.y + s.w.z * s.w.z));
            WORK_T(1);
            if (sc_meets(c0.x, c0.y, c0.z, r0, a, w)) {
                buf[nb].org_tmax = a;
                buf[nb].dir_inv2 = w;
                slots[nb] = slot;
                if (++nb == SC_GATHER_BUF) {
                    sc_flush(rec0, slot0, n0, buf, slots, nb);
                    nb = 0;
                }
            }
        }
    }
    if (nb) sc_flush(rec0, slot0, n0, buf, slots, nb);
    WORK_FLUSH(work);
}

/* Rebuild a list (centre c, radius r) by testing the parent's records
   [beg, end) of (prec, pslot) and appending copies of those that meet the
   sphere to (rec, slot) from `top`. Returns the new top, which may exceed
   cap (entries past cap are counted, not stored; the caller gives up the
   point). Copies, not indices: the deep lists are small and are rebuilt
   most often, and copies keep them contiguous and in cache, where indices
   into the batch-wide list0 made most tests cache misses (about 2x slower
   overall on 10^6 segments). The tests of 32 entries are done first, into a bit mask,
   then only the hits are stored: no data-dependent branch per test and no
   chain through `top` while testing (faster than both a branch per test
   and an unconditional store). Past cap, stores go to the spare entry. */
inline int sc_rebuild(float cx, float cy, float cz, float r, __global const ScRecord *prec,
                      __global const int *pslot, int beg, int end, __global ScRecord *rec, __global int *slot,
                      int top, int cap)
{
    for (int i0 = beg; i0 < end; i0 += 32) {
        int n = min(32, end - i0);
        uint m = 0u;
        for (int l = 0; l < n; ++l)
            m |= (uint)sc_meets(cx, cy, cz, r, prec[i0 + l].org_tmax, prec[i0 + l].dir_inv2) << l;
        while (m) {
            int i = i0 + lowest_bit(m);
            m &= m - 1u;
            int j = min(top++, cap);
            rec[j] = prec[i];
            slot[j] = pslot[i];
        }
    }
    return top;
}

/* Deepest j such that spheres 1..j (of the nv valid ones) all hold the disc. */
inline int sc_prefix(float x, float y, float z, float d, int nv, const float4 *centre, const float *rad)
{
    int j = 0;
    for (; j < nv; ++j) {
        float4 c = centre[j + 1];
        float dx = x - c.x, dy = y - c.y, dz = z - c.z;
        if (!(sqrt(dx * dx + dy * dy + dz * dz) + d <= rad[j + 1])) break;
    }
    return j;
}

/* Rebuild list k of the stack (k >= 1) around c; lend[k] = its new end. */
#define SC_REBUILD(k, cx, cy, cz)                                                                    \
    (lend[k] = (k) == 1 ? sc_rebuild(cx, cy, cz, rad[1], rec0, slot0, 0, n0, rec, slot, 0, cap)      \
                        : sc_rebuild(cx, cy, cz, rad[k], rec, slot, (k) > 2 ? lend[(k) - 2] : 0,     \
                                     lend[(k) - 1], rec, slot, lend[(k) - 1], cap))

__kernel void sc_runs(__global const float4 *positions, __global const float4 *normals,
                      __global const int *perm, int n_points, int run_length,
                      __global const int *runs, int run_base, int n_launch, __global int *run_done,
                      __global const ScRecord *rec0, __global const int *slot0, int first, int n0,
                      __global const Segment *segments, __global const float *radii, int levels,
                      float radius, float radius2, __global ScRecord *srec, __global int *sslot,
                      int cap, __global long *acc, volatile __global int *status, __global ulong *work)
{
    int g = get_global_id(0);
    if (g >= n_launch) return;
    int run = runs[run_base + g];
    int start = run * run_length;
    int end = min(n_points, start + run_length);
    int resume = start + run_done[run];
    if (resume >= end) return;
    rec0 += first; /* this launch's piece of list 0: [first, first + n0) */
    slot0 += first;
    /* this run's stack: cap entries + the spare one */
    __global ScRecord *rec = srec + (size_t)g * (cap + 1);
    __global int *slot = sslot + (size_t)g * (cap + 1);
    WORK_DECL;

    float rad[OCLGI_SC_MAX_LEVELS + 1];
    float4 centre[OCLGI_SC_MAX_LEVELS + 1];
    int lend[OCLGI_SC_MAX_LEVELS + 1]; /* list k = stack [lend[k-1], lend[k]) (lend[0] = 0) */
    int L = levels;
    for (int k = 0; k <= L; ++k) rad[k] = radii[k];
    lend[0] = 0;
    int nv = 0; /* spheres 1..nv are valid */
    int peak = 0;

    /* Resumed after an overflow: replay the centres of the run's earlier
       points (no list work), then rebuild their lists, uncounted. */
    if (resume > start && L > 0) {
        for (int pos = start; pos < resume; ++pos) {
            float4 x = positions[perm[pos]], n = normals[perm[pos]];
            if (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) continue; /* as below */
            x.w = 0.0f;
            for (int k = sc_prefix(x.x, x.y, x.z, radius, nv, centre, rad) + 1; k <= L; ++k) centre[k] = x;
            nv = L;
        }
        for (int k = 1; k <= L; ++k) {
            SC_REBUILD(k, centre[k].x, centre[k].y, centre[k].z);
            if (lend[k] > cap) {
                atomic_max(&status[1], lend[k]);
                atomic_xchg(&status[0], 1);
                return;
            }
        }
    }

    for (int pos = resume; pos < end; ++pos) {
        int i = perm[pos];
        float4 x = positions[i], n = normals[i];
        /* No normal (a camera pixel that sees nothing): DETP_TEST can never
           accept a segment, so the point keeps its zero sums without moving
           the spheres or being counted; its position may be anywhere. */
        if (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) continue;
        x.w = 0.0f; /* the triangle's int bits: a denormal, kept out of any float arithmetic */
        ulong pt = 0, pu; /* this point's counts, committed only when it completes */
        for (int k = (L > 0 ? sc_prefix(x.x, x.y, x.z, radius, nv, centre, rad) : 0) + 1; k <= L; ++k) {
            pt += k > 1 ? (ulong)(lend[k - 1] - (k > 2 ? lend[k - 2] : 0)) : (ulong)n0;
            centre[k] = x;
            SC_REBUILD(k, x.x, x.y, x.z);
            if (lend[k] > cap) {
                /* Stop before this point: the run resumes here with a larger cap. */
                run_done[run] = pos - start;
                atomic_max(&status[1], lend[k]);
                atomic_xchg(&status[0], 1);
                atomic_max(&status[2], peak);
                WORK_FLUSH(work);
                return;
            }
        }
        nv = L;
        peak = max(peak, lend[L]);

        /* DETP on the innermost list (list0 itself when there is no inner sphere). */
        __global const ScRecord *ir = L > 0 ? rec : rec0;
        __global const int *is = L > 0 ? slot : slot0;
        int beg = L > 1 ? lend[L - 1] : 0, stop = L > 0 ? lend[L] : n0;
        pu = (ulong)(stop - beg);
        long sr = 0, sg = 0, sb = 0;
        for (int j = beg; j < stop; ++j) {
            float4 a = ir[j].org_tmax, b = ir[j].dir_inv2;
            int hit;
            DETP_TEST(float, hit, x.x, x.y, x.z, n.x, n.y, n.z, a.x, a.y, a.z, b.x, b.y, b.z, a.w, radius2);
            if (hit) {
                long3 p = segment_fixed_power(segments + is[j]); /* as detp.cl */
                sr += p.x;
                sg += p.y;
                sb += p.z;
            }
        }
        acc[3 * i + 0] += sr;
        acc[3 * i + 1] += sg;
        acc[3 * i + 2] += sb;
        WORK_T(pt);
        WORK_U(pu);
    }
    run_done[run] = end - start;
    atomic_max(&status[2], peak);
    WORK_FLUSH(work);
}
