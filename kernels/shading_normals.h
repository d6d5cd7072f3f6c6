/* shading_normals.h: a mesh's interpolated vertex normals at a point
 * (oclgi/scene/shading_normals.py packs them and says where they are used).
 *
 * shading_normal  the normal at world point p of triangle tri: its object
 *                 space point, through the triangle's affine map (three
 *                 float4 rows, as the vertex colours' in texture.h), back
 *                 to world space through the inverse transpose of the
 *                 instance's transform (as instances.cl turns the geometric
 *                 normals), on the side of ng (the geometric normal turned
 *                 towards the arriving ray). A triangle without vertex
 *                 normals (an all-zero map), or whose interpolated normal
 *                 vanishes (corner normals that cancel), gives ng itself.
 *                 *smooth says which.
 */
#ifndef OCLGI_SHADING_NORMALS_H
#define OCLGI_SHADING_NORMALS_H

#include "bvh.h"

inline float3 shading_normal(__global const float4 *tri_shading, __global const int *tri_object,
                             __global const Instance *poses, int tri, float3 p, float3 ng, int *smooth)
{
    __global const float4 *s = &tri_shading[3 * tri];
    *smooth = 0;
    if (!any(s[0] != 0.0f) && !any(s[1] != 0.0f) && !any(s[2] != 0.0f)) return ng;
    __global const float *m = poses[tri_object[tri]].object_from_world;
    float3 q = xform_point(m, p);
    float3 n = (float3)(dot(s[0].xyz, q) + s[0].w, dot(s[1].xyz, q) + s[1].w, dot(s[2].xyz, q) + s[2].w);
    float3 w = (float3)(m[0] * n.x + m[4] * n.y + m[8] * n.z, /* (M^-1)^T n: columns of M^-1 */
                        m[1] * n.x + m[5] * n.y + m[9] * n.z,
                        m[2] * n.x + m[6] * n.y + m[10] * n.z);
    float len2 = dot(w, w);
    if (!(len2 > 1e-12f)) return ng;
    w *= rsqrt(len2);
    *smooth = 1;
    return dot(w, ng) < 0.0f ? -w : w;
}

#endif
