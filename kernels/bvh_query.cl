/* bvh_query.cl: batches of ray queries against the scene BVH.
 *
 * Rays come as the caller's arrays, read in place (oclgi/accel/bvh.py
 * wraps numpy's memory on a CPU device): origins and directions as packed
 * float triples (n x 3), and a distance limit per ray, tmax[i * tmax_step]
 * (tmax_step 0: one limit for every ray). Packing them into float4s first
 * cost more than a query of rays that miss everything.
 *
 * bvh_query_closest  one work-item per ray: hits (t, u, v, as_float(tri)) out.
 * bvh_query_any      one work-item per ray: 1 when anything is hit before tmax.
 * bvh_query_count   (built with OCLGI_BVH_COUNT=1) one work-item per ray: the
 *                    closest hit's traversal work, nodes visited and
 *                    triangles tested.
 * bvh_query_locate   one work-item per point: the triangle under a point
 *                    (within delta along its normal, either side) and the
 *                    barycentrics of the foot point; tri = -1 when none.
 */
#include "bvh.h"

#define RAY_ARGS __global const float *origins, __global const float *dirs, __global const float *tmax, int tmax_step
#define RAY_O(i) vload3((i), origins)
#define RAY_D(i) vload3((i), dirs)
#define RAY_TMAX(i) tmax[(size_t)(i) * tmax_step]

__kernel void bvh_query_closest(SCENE_ARGS, RAY_ARGS, int n, __global float4 *hits)
{
    int i = get_global_id(0);
    if (i >= n) return;
    Hit h;
    scene_closest_hit(SCENE_PASS, RAY_O(i), RAY_D(i), RAY_TMAX(i), &h);
    hits[i] = (float4)(h.tri >= 0 ? h.t : INFINITY, h.u, h.v, as_float(h.tri));
}

__kernel void bvh_query_any(SCENE_ARGS, RAY_ARGS, int n, __global int *hit)
{
    int i = get_global_id(0);
    if (i >= n) return;
    hit[i] = scene_any_hit(SCENE_PASS, RAY_O(i), RAY_D(i), RAY_TMAX(i));
}

#if OCLGI_BVH_COUNT
__kernel void bvh_query_count(SCENE_ARGS, RAY_ARGS, int n, __global int2 *work)
{
    int i = get_global_id(0);
    if (i >= n) return;
    Hit h;
    h.nodes = 0;
    h.tests = 0;
    scene_closest_hit(SCENE_PASS, RAY_O(i), RAY_D(i), RAY_TMAX(i), &h);
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
