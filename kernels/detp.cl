/* detp.cl: plain DETP, the oracle for every accelerated variant.
 *
 * detp_plain    one work-item per OCLGI_LANES (8) consecutive query points,
 *               held in float8 lanes: every segment slot of a batch
 *               (n_slots = paths * max_depth, read by segment.h) is
 *               tested against the 8 discs at once with DETP_TEST (detp.h),
 *               and the fixed-point power of a crossing segment is added to
 *               that point's sums. Each point has its own squared radius
 *               (radius2[i]: the one radius of the run, or per-point
 *               adaptive radii, oclgi/estimators/adaptive_radius.py). A
 *               work-item owns its points, so no atomics; batches run in
 *               order. (PoCL does not vectorise loops across work-items, so
 *               the lanes are explicit.)
 *               Counts u = segment-disc tests (work.h).
 * detp_resolve  (detp_resolve.h) one work-item per point: E = acc / (scale * pi d^2);
 *               detp_resolve_radii the same with each point's own d.
 *
 * count_emitted = 0 skips segments leaving the light (bounce 0, segment.h),
 * i.e. the estimate is of indirect light only.
 */
#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "work.h"
#include "detp_resolve.h"

__kernel void detp_plain(__global const float4 *positions, __global const float4 *normals,
                         int n_points, __global const Segment *segments, int n_paths,
                         int max_depth, int count_emitted, __global const float *radius2, float ext,
                         __global long *acc, __global ulong *work)
{
    int base = get_global_id(0) * OCLGI_LANES;
    if (base >= n_points) return;
    WORK_DECL;
    int lanes = min(OCLGI_LANES, n_points - base); /* real points in this work-item */
    float px[OCLGI_LANES], py[OCLGI_LANES], pz[OCLGI_LANES], qx[OCLGI_LANES], qy[OCLGI_LANES], qz[OCLGI_LANES];
    float rr[OCLGI_LANES];
    for (int k = 0; k < OCLGI_LANES; ++k) {
        int i = min(base + k, n_points - 1);
        float4 p = positions[i], n = normals[i];
        if (base + k >= n_points) n = (float4)(0.0f); /* padding lane: never crosses */
        px[k] = p.x; py[k] = p.y; pz[k] = p.z; qx[k] = n.x; qy[k] = n.y; qz[k] = n.z;
        rr[k] = radius2[i];
    }
    float8 x = vload8(0, px), y = vload8(0, py), z = vload8(0, pz);
    float8 nx = vload8(0, qx), ny = vload8(0, qy), nz = vload8(0, qz);
    float8 r2 = vload8(0, rr);
    /* Per-lane sums in long4 halves: a long8 (512 bits) through a builtin
     * (convert_long8, vstore8) changes the calling convention without
     * AVX-512, a compiler warning on AVX2; 256-bit vectors do not, and the
     * halves compile to the same loop as the long8 did. */
    long4 sr0 = 0, sr1 = 0, sg0 = 0, sg1 = 0, sb0 = 0, sb1 = 0;
    for (int p = 0; p < n_paths; ++p) {
        __global const Segment *path = segments + (size_t)p * max_depth;
        for (int b = segment_first(count_emitted); b < max_depth; ++b) {
            SegmentView s;
            if (!segment_read(path + b, &s)) {
                if (segment_is_hole(path + b)) continue;
                break; /* the path's end */
            }
            float tmax = s.t_end + ext;
            WORK_U(lanes);
            int8 hit;
            DETP_TEST(float8, hit, x, y, z, nx, ny, nz, s.o.x, s.o.y, s.o.z, s.w.x, s.w.y, s.w.z, tmax, r2);
            if (any(hit)) {
                long3 q = segment_fixed_power(path + b);
                long4 m0 = convert_long4(hit.lo) & 1, m1 = convert_long4(hit.hi) & 1;
                sr0 += m0 * q.x; sr1 += m1 * q.x;
                sg0 += m0 * q.y; sg1 += m1 * q.y;
                sb0 += m0 * q.z; sb1 += m1 * q.z;
            }
        }
    }
    long r[OCLGI_LANES], g[OCLGI_LANES], bl[OCLGI_LANES];
    vstore4(sr0, 0, r); vstore4(sr1, 1, r);
    vstore4(sg0, 0, g); vstore4(sg1, 1, g);
    vstore4(sb0, 0, bl); vstore4(sb1, 1, bl);
    for (int k = 0; k < OCLGI_LANES && base + k < n_points; ++k) {
        int i = base + k;
        acc[3 * i + 0] += r[k];
        acc[3 * i + 1] += g[k];
        acc[3 * i + 2] += bl[k];
    }
    WORK_FLUSH(work);
}
