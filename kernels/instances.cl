/* instances.cl: keeping the world form of a moved object up to date.
 *
 * instances_normals  one work-item per triangle of instance k: its world
 *                    normal, the object normal through the inverse transpose
 *                    of the instance's transform (right for any invertible
 *                    affine map, not only rigid ones), renormalised.
 */
#include "oclgi_types.h"

__kernel void instances_normals(__global const float4 *object_normals,
                                __global const Instance *instances, int k,
                                __global float4 *world_normals)
{
    int i = get_global_id(0);
    __global const Instance *in = &instances[k];
    if (i >= in->n_tris) return;
    int t = in->first_tri + i;
    float3 n = object_normals[t].xyz;
    __global const float *m = in->object_from_world; /* (M^-1)^T n: columns of M^-1 */
    float3 w = (float3)(m[0] * n.x + m[4] * n.y + m[8] * n.z,
                        m[1] * n.x + m[5] * n.y + m[9] * n.z,
                        m[2] * n.x + m[6] * n.y + m[10] * n.z);
    world_normals[t] = (float4)(normalize(w), 0.0f);
}
