/* update.cl: finding and gathering the paths a move changes (DESIGN.md 4).
 *
 * update_first_affected  one work-item per stored path: the first bounce b
 *     whose segment hit the moved object before the move (its triangle is
 *     in the object's range) or meets the object at its new pose before its
 *     own end (the object's box first, then its BVH, any hit, with the same
 *     traversal code and transform as a full trace uses, so the answer
 *     agrees with a re-trace exactly); -1 when the path is untouched. The
 *     segments before b are the same in the moved scene, so re-tracing from
 *     b gives the recomputed path.
 * update_gather  one work-item per listed path: copies its slots from its
 *     first affected bounce on, with the power times sign (-1 takes a
 *     contribution away: round-to-nearest-even is symmetric, so the
 *     fixed-point sums lose exactly what they gained), into a path-major
 *     scratch store that every estimator accumulates like a batch. Slots
 *     before b become holes (zero, tri = SEGMENT_HOLE): skipped, not ends.
 */
#include "bvh.h"

__kernel void update_first_affected(SCENE_ARGS, int obj, __global const Segment *segments, int n_paths,
                                    int max_depth, __global int *first)
{
    int p = get_global_id(0);
    if (p >= n_paths) return;
    __global const Instance *in = &instances[obj];
    int lo = in->first_tri, hi = in->first_tri + in->n_tris;
    int found = -1;
    for (int b = 0; b < max_depth && found < 0; ++b) {
        __global const Segment *sg = &segments[(size_t)p * max_depth + b];
        float3 d = vload3(0, sg->dir);
        if (d.x == 0.0f && d.y == 0.0f && d.z == 0.0f) break; /* the path's end */
        if (sg->tri >= lo && sg->tri < hi) { found = b; break; }
        float3 o = vload3(0, sg->org);
        if (box_entry(in->lo, in->hi, o, 1.0f / d, sg->t_end) == INFINITY) continue;
        Hit h;
        h.tri = -1;
        h.t = sg->t_end;
        if (bvh_traverse(nodes, tris, in->root, xform_point(in->object_from_world, o),
                         xform_vector(in->object_from_world, d), 1, &h) >= 0)
            found = b;
    }
    first[p] = found;
}

__kernel void update_gather(__global const Segment *segments, int max_depth,
                            __global const int *paths, __global const int *starts, int n_list,
                            float sign, __global Segment *out)
{
    int k = get_global_id(0);
    if (k >= n_list) return;
    __global const Segment *src = &segments[(size_t)paths[k] * max_depth];
    __global Segment *dst = &out[(size_t)k * max_depth];
    int b0 = starts[k];
    for (int b = 0; b < max_depth; ++b) {
        Segment s = src[b];
        if (b < b0) {
            s = (Segment){{0.0f, 0.0f, 0.0f}, 0.0f, {0.0f, 0.0f, 0.0f}, SEGMENT_HOLE, {0.0f, 0.0f, 0.0f}, s.path};
        } else {
            s.power[0] *= sign;
            s.power[1] *= sign;
            s.power[2] *= sign;
        }
        dst[b] = s;
    }
}
