/* photon_map.cl: Photon Maps (Jensen 1995): the impacts of a batch and the
 * estimate from the k nearest (the search itself: point_index.cl).
 *
 * pm_count     one work-item per path of a batch: how many impacts it has
 *              (pm_stored: segments that end on a surface, segment.h,
 *              other than a mirror's or glass's, where no density is
 *              estimated (Jensen); bounce 0 skipped unless count_emitted).
 *              The host turns the counts into offsets.
 * pm_gather    one work-item per path: writes its impacts at its offset, in
 *              bounce order (so a run's impacts come out in (path, bounce)
 *              order, the canonical order whatever the batch size):
 *              position (segment_end), arriving direction, power, as
 *              packed float3 arrays.
 * pm_resolve   one work-item per point: E = acc / (scale pi r_K^2), 0 when
 *              fewer than K impacts were found.
 */
#include "point_index.h"

#define PM_MATERIALS __global const int *tri_material, __global const Material *materials

inline int pm_stored(__global const Segment *slot, PM_MATERIALS)
{
    return segment_impact(slot) && !(materials[tri_material[slot->tri]].flags & OCLGI_MATERIAL_DELTA);
}

__kernel void pm_count(__global const Segment *segments, int n_paths, int max_depth,
                       int count_emitted, PM_MATERIALS, __global int *counts)
{
    int p = get_global_id(0);
    if (p >= n_paths) return;
    __global const Segment *path = segments + (size_t)p * max_depth;
    int c = 0;
    for (int b = segment_first(count_emitted); b < max_depth; ++b) {
        SegmentView s;
        if (!segment_read(path + b, &s)) {
            if (segment_is_hole(path + b)) continue;
            break; /* the path's end */
        }
        c += pm_stored(path + b, tri_material, materials);
    }
    counts[p] = c;
}

__kernel void pm_gather(__global const Segment *segments, int n_paths, int max_depth,
                        int count_emitted, PM_MATERIALS, __global const int *offsets,
                        __global float *pos, __global float *dir, __global float *power)
{
    int p = get_global_id(0);
    if (p >= n_paths) return;
    __global const Segment *path = segments + (size_t)p * max_depth;
    int o = offsets[p];
    for (int b = segment_first(count_emitted); b < max_depth; ++b) {
        SegmentView s;
        if (!segment_read(path + b, &s)) {
            if (segment_is_hole(path + b)) continue;
            break; /* the path's end */
        }
        if (!pm_stored(path + b, tri_material, materials)) continue;
        vstore3(segment_end(&s), o, pos);
        vstore3(s.w, o, dir);
        vstore3(segment_power(path + b), o, power);
        ++o;
    }
}

__kernel void pm_resolve(__global const long *acc, __global const float *r2, int n_points,
                         float inv_scale_pi, __global float4 *irradiance)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    float r = r2[i];
    float k = r > 0.0f && r != INFINITY ? inv_scale_pi / r : 0.0f;
    irradiance[i] = (float4)((float)acc[3 * i], (float)acc[3 * i + 1], (float)acc[3 * i + 2], 0.0f) * k;
}
