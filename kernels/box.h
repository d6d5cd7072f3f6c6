/* box.h: the one slab test of a ray or segment against an axis-aligned box,
 * for the scene's BVH (bvh.h), the disc index's tree (box_wide.h) and the cell
 * masks of a session's paths (update.cl).
 */
#ifndef OCLGI_BOX_H
#define OCLGI_BOX_H

#pragma OPENCL FP_CONTRACT OFF

/* Does o + t w, 0 <= t <= tmax, meet the box [lo, hi]? inv = 1 / w; tmax
 * may be INFINITY (escaping segments, rays without a limit): the slabs clip
 * it. *enter is where it enters (>= 0) when it does. fmin/fmax drop the NaN
 * of 0 * inf (o on a slab plane, w parallel to it); the far end gets 1 + 2
 * ulp-ish of slack, so grazing rays and segments are kept, never dropped. */
inline int box_slab(float3 lo, float3 hi, float3 o, float3 inv, float tmax, float *enter)
{
    float3 t0 = (lo - o) * inv;
    float3 t1 = (hi - o) * inv;
    float3 tn = fmin(t0, t1), tf = fmax(t0, t1);
    float e = fmax(fmax(tn.x, tn.y), fmax(tn.z, 0.0f));
    float leave = fmin(fmin(tf.x, tf.y), fmin(tf.z, tmax)) * 1.0000004f;
    *enter = e;
    return e <= leave;
}

#endif
