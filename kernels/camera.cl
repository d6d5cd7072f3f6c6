/* camera.cl: the visible point of each pixel, as DETP/Impact Count queries.
 *
 * camera_visible_points  one work-item per pixel of the rectangle x0, y0,
 *     rw x rh of a width x height image (row-major, top row first; outputs
 *     are the rectangle's pixels, row-major): a pinhole ray through the
 *     pixel's point `offset` (in pixel units from its top-left corner: 0.5,
 *     0.5 is the centre; a render of several samples per pixel launches
 *     once per sample) against the instances given (all of them, or a subset: a
 *     session's static layer); on a hit, the point (w =
 *     as_float(tri)), the geometric normal turned towards the camera (w = 1
 *     when the triangle's own normal faces the camera, which is when a
 *     one-sided emitter is seen) and the hit barycentrics; tri = -1 on a miss.
 */
#include "bvh.h"

__kernel void camera_visible_points(SCENE_ARGS,
                                    __global const float4 *tri_normals,
                                    float4 eye, float4 forward, float4 right, float4 up,
                                    int width, int height, int x0, int y0, int rw, int rh, float2 offset,
                                    __global float4 *positions, __global float4 *normals,
                                    __global float2 *barys)
{
    int i = get_global_id(0);
    if (i >= rw * rh) return;
    int px = x0 + i % rw, py = y0 + i / rw;
    /* right and up are pre-scaled by the half-extents of the image plane */
    float sx = 2.0f * ((float)px + offset.x) / (float)width - 1.0f;
    float sy = 1.0f - 2.0f * ((float)py + offset.y) / (float)height;
    float3 d = normalize(forward.xyz + sx * right.xyz + sy * up.xyz);
    Hit h;
    scene_closest_hit(SCENE_PASS, eye.xyz, d, INFINITY, &h);
    if (h.tri < 0) {
        positions[i] = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
        normals[i] = (float4)(0.0f); /* a zero normal: no estimator counts anything here */
        barys[i] = (float2)(0.0f);
        return;
    }
    float3 n = tri_normals[h.tri].xyz;
    float front = dot(n, d) < 0.0f ? 1.0f : 0.0f;
    if (front == 0.0f) n = -n;
    positions[i] = (float4)(eye.xyz + h.t * d, as_float(h.tri));
    normals[i] = (float4)(n, front);
    barys[i] = (float2)(h.u, h.v);
}
