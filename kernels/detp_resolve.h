/* detp_resolve.h: the resolve step shared by every DETP variant,
 * E = acc / (scale pi d^2), one work-item per point; detp_resolve_radii
 * with each point's own radius d_i (adaptive radii):
 * E_i = acc_i * (1 / (scale pi)) * (1 / d_i^2).
 *
 * A kernel in a header: each DETP program (detp.cl, detp_disc_index.cl,
 * detp_ray_map.cl, detp_sphere_cache.cl) carries its own copy, so that a
 * run builds one program for its estimator rather than two (a cold build
 * of a program costs a few tenths of a second). Every copy is the same code,
 * so every variant resolves the same sums to the same bits.
 */
#ifndef OCLGI_DETP_RESOLVE_H
#define OCLGI_DETP_RESOLVE_H

__kernel void detp_resolve(__global const long *acc, int n_points, float inv_norm,
                           __global float4 *irradiance)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    irradiance[i] = (float4)((float)acc[3 * i], (float)acc[3 * i + 1], (float)acc[3 * i + 2], 0.0f)
                    * inv_norm;
}

__kernel void detp_resolve_radii(__global const long *acc, int n_points, float inv_scale_pi,
                                 __global const float *inv_radius2, __global float4 *irradiance)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    float inv_norm = inv_scale_pi * inv_radius2[i];
    irradiance[i] = (float4)((float)acc[3 * i], (float)acc[3 * i + 1], (float)acc[3 * i + 2], 0.0f)
                    * inv_norm;
}

#endif
