/* bsdf_probe.cl: bsdf.h's verbs, one work-item per query, for the tests
 * (tests/test_bsdf.py: chi-square of the sampled directions against the
 * pdf, reciprocity, the white furnace, weight = f cos / pdf). The product
 * calls the same inline functions from photon_trace.cl and camera.cl.
 *
 * bsdf_probe_sample  material m, normal n, wo[i], u[i] -> wi[i] (w: flags
 *                    as int bits), weight[i]
 * bsdf_probe_eval    m, n, wo[i], wi[i] -> f[i] (xyz) and pdf (w)
 */
#include "bsdf.h"

__kernel void bsdf_probe_sample(__global const Material *m, float4 n, __global const float4 *wo,
                                __global const float4 *u, int adjoint, int count, __global float4 *wi,
                                __global float4 *weight)
{
    int i = get_global_id(0);
    if (i >= count) return;
    BsdfSample s = bsdf_sample(m, n.xyz, wo[i].xyz, u[i], adjoint);
    wi[i] = (float4)(s.wi, as_float(s.flags));
    weight[i] = (float4)(s.weight, 0.0f);
}

__kernel void bsdf_probe_eval(__global const Material *m, float4 n, __global const float4 *wo,
                              __global const float4 *wi, int adjoint, int count, __global float4 *out)
{
    int i = get_global_id(0);
    if (i >= count) return;
    out[i] = (float4)(bsdf_eval(m, n.xyz, wo[i].xyz, wi[i].xyz, adjoint), bsdf_pdf(m, n.xyz, wo[i].xyz, wi[i].xyz));
}
