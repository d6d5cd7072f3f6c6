/* bvh_query.cl: batches of ray queries against the scene BVH.
 *
 * bvh_query_closest  one work-item per ray: origins (xyz, w = tmax) and
 *                    directions (xyz) in, hits (t, u, v, as_float(tri)) out.
 * bvh_query_any      one work-item per ray: 1 when anything is hit before tmax.
 * bvh_query_count   (built with OCLGI_BVH_COUNT=1) one work-item per ray: the
 *                    closest hit's traversal work, nodes visited and
 *                    triangles tested.
 * bvh_query_locate   one work-item per point: the triangle under a point
 *                    (within delta along its normal, either side) and the
 *                    barycentrics of the foot point; tri = -1 when none.
 */
#include "bvh.h"

__kernel void bvh_query_closest(SCENE_ARGS,
                                __global const float4 *origins, __global const float4 *dirs,
                                int n, __global float4 *hits)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = origins[i];
    Hit h;
    scene_closest_hit(SCENE_PASS, o.xyz, dirs[i].xyz, o.w, &h);
    hits[i] = (float4)(h.tri >= 0 ? h.t : INFINITY, h.u, h.v, as_float(h.tri));
}

__kernel void bvh_query_any(SCENE_ARGS,
                            __global const float4 *origins, __global const float4 *dirs,
                            int n, __global int *hit)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = origins[i];
    hit[i] = scene_any_hit(SCENE_PASS, o.xyz, dirs[i].xyz, o.w);
}

#if OCLGI_BVH_COUNT
__kernel void bvh_query_count(SCENE_ARGS,
                              __global const float4 *origins, __global const float4 *dirs,
                              int n, __global int2 *work)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float4 o = origins[i];
    Hit h;
    h.nodes = 0;
    h.tests = 0;
    scene_closest_hit(SCENE_PASS, o.xyz, dirs[i].xyz, o.w, &h);
    work[i] = (int2)(h.nodes, h.tests);
}
#endif

__kernel void bvh_query_locate(SCENE_ARGS,
                               __global float4 *positions, __global const float4 *normals,
                               int n, float delta, __global float2 *barys)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float3 p = positions[i].xyz, nrm = normals[i].xyz;
    Hit h;
    /* from above the surface down, then from below up */
    if (scene_closest_hit(SCENE_PASS, p + delta * nrm, -nrm, 2.0f * delta, &h) < 0)
        scene_closest_hit(SCENE_PASS, p - delta * nrm, nrm, 2.0f * delta, &h);
    positions[i].w = as_float(h.tri);
    barys[i] = h.tri >= 0 ? (float2)(h.u, h.v) : (float2)(0.0f, 0.0f);
}
