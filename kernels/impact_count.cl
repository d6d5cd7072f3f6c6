/* impact_count.cl: Impact Count (Arvo 1986) with vertex averaging.
 *
 * impact_count_accumulate   one work-item per segment slot: an impact
 *                           (segment.h) on triangle t adds its fixed-point
 *                           power to t's three accumulators (64-bit atomics).
 * impact_count_triangles    one work-item per triangle: E = acc / (scale A).
 * impact_count_vertices     one work-item per vertex: the mean of its
 *                           triangles' irradiance (CSR vertex -> triangles).
 * impact_count_interpolate  one work-item per query point on triangle t with
 *                           barycentrics (u, v): linear interpolation of the
 *                           vertex values.
 */
#include "oclgi_types.h"
#include "segment.h"

__kernel void impact_count_accumulate(__global const Segment *segments, int n_slots,
                                      int max_depth, int count_emitted,
                                      __global long *acc)
{
    int s = get_global_id(0);
    if (s >= n_slots) return;
    __global const Segment *slot = &segments[s];
    if (!segment_impact(slot) || !segment_counted(s % max_depth, count_emitted)) return;
    int t = slot->tri;
    long3 q = segment_fixed_power(slot);
    atom_add(&acc[3 * t + 0], q.x);
    atom_add(&acc[3 * t + 1], q.y);
    atom_add(&acc[3 * t + 2], q.z);
}

__kernel void impact_count_triangles(__global const long *acc, __global const float *areas,
                                     int n_tris, float inv_scale, __global float4 *tri_irradiance)
{
    int t = get_global_id(0);
    if (t >= n_tris) return;
    float k = inv_scale / areas[t];
    tri_irradiance[t] = (float4)((float)acc[3 * t], (float)acc[3 * t + 1], (float)acc[3 * t + 2], 0.0f) * k;
}

__kernel void impact_count_vertices(__global const float4 *tri_irradiance,
                                    __global const int *vertex_tri_starts,
                                    __global const int *vertex_tri_lists, int n_vertices,
                                    __global float4 *vertex_irradiance)
{
    int v = get_global_id(0);
    if (v >= n_vertices) return;
    int a = vertex_tri_starts[v], b = vertex_tri_starts[v + 1];
    float4 sum = (float4)(0.0f);
    for (int k = a; k < b; ++k) sum += tri_irradiance[vertex_tri_lists[k]];
    vertex_irradiance[v] = b > a ? sum / (float)(b - a) : sum;
}

__kernel void impact_count_interpolate(__global const float4 *positions, __global const float2 *barys,
                                       int n_points, __global const int *faces,
                                       __global const float4 *vertex_irradiance,
                                       __global float4 *irradiance)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    int t = as_int(positions[i].w);
    if (t < 0) { irradiance[i] = (float4)(0.0f); return; } /* camera miss */
    float2 b = barys[i];
    irradiance[i] = (1.0f - b.x - b.y) * vertex_irradiance[faces[3 * t]]
                  + b.x * vertex_irradiance[faces[3 * t + 1]]
                  + b.y * vertex_irradiance[faces[3 * t + 2]];
}
