/* detp.h: the one definition of "segment crosses the disc" (DESIGN.md 3).
 *
 * Disc of radius d centred on x, tangent to the surface (unit normal n).
 * A segment (o, w, t_end) counts when
 *   1. it arrives on the front side:   wn = w.n < -OCLGI_FRONT_COS_EPS
 *   2. it crosses the plane in range:  0 < t* <= t_end + ext, t* = num / wn,
 *                                       num = (x - o).n
 *   3. the crossing is in the disc:     |o + t* w - x|^2 <= d^2
 * ext is the user's extension e plus a small scene-relative tolerance, so
 * segments ending on the disc's own surface are not lost to float rounding.
 *
 * Written without division (wn < 0): 2. is num < 0 and num >= (t_end+ext) wn;
 * 3. is |num w - wn (x - o)|^2 <= d^2 wn^2. Contraction into FMAs is off and
 * the operation order is fixed in one macro, used for scalars and vectors
 * alike, so every DETP variant (plain, sphere cache, disc index, ray map;
 * scalar or SIMD) selects exactly the same segments.
 */
#ifndef OCLGI_DETP_H
#define OCLGI_DETP_H

#pragma OPENCL FP_CONTRACT OFF

#include "constants.h"

/* Surface-consistent counting (the estimators' option ``consistent``): a
 * segment also has to END near the disc's plane, within SPAN after
 * crossing it (t* >= t_end + ext - SPAN, SPAN = ext + the option's span),
 * so that a ray which crosses the disc where the surface is not (beside a
 * leaf smaller than the disc, through a gap) and goes on to land elsewhere
 * is not counted. Division-free as the rest: num <= (tmax - SPAN) wn.
 * Built in when OCLGI_CONSISTENT_SPAN is defined (a float, the build's). */
#ifdef OCLGI_CONSISTENT_SPAN
#define DETP_CONSISTENT(res, num, wn, tmax) res = (res) & ((num) <= ((tmax) - (OCLGI_CONSISTENT_SPAN)) * (wn))
#else
#define DETP_CONSISTENT(res, num, wn, tmax)
#endif

/* res = the test's truth value (1 for scalars, -1 lanes for vectors).
 * p*: disc centre, n*: disc normal, o*: segment origin, w*: direction,
 * tmax = t_end + ext, r2 = d^2. T is the type of the point-side values. */
#define DETP_TEST(T, res, px, py, pz, nx, ny, nz, ox, oy, oz, wx, wy, wz, tmax, r2)  \
    do {                                                                            \
        T ax_ = (px) - (ox), ay_ = (py) - (oy), az_ = (pz) - (oz);                  \
        T wn_ = (wx) * (nx) + (wy) * (ny) + (wz) * (nz);                            \
        T num_ = ax_ * (nx) + ay_ * (ny) + az_ * (nz);                              \
        T cx_ = num_ * (wx) - wn_ * ax_;                                            \
        T cy_ = num_ * (wy) - wn_ * ay_;                                            \
        T cz_ = num_ * (wz) - wn_ * az_;                                            \
        res = (wn_ < -OCLGI_FRONT_COS_EPS) & (num_ < 0.0f) & (num_ >= (tmax) * wn_) \
            & (cx_ * cx_ + cy_ * cy_ + cz_ * cz_ <= (r2) * (wn_ * wn_));             \
        DETP_CONSISTENT(res, num_, wn_, (tmax));                                    \
    } while (0)

inline int detp_crosses(float3 x, float3 n, float radius2, float ext,
                        float3 o, float3 w, float t_end)
{
    int res;
    float tmax = t_end + ext;
    DETP_TEST(float, res, x.x, x.y, x.z, n.x, n.y, n.z, o.x, o.y, o.z, w.x, w.y, w.z, tmax, radius2);
    return res;
}

#endif
