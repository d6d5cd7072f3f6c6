/* photon_map_update.cl: the update of a Photon Map session after a move
 * (oclgi/photon_map_session.py, DESIGN.md section 4).
 *
 * Every query point i has a ball: centre x_i, squared radius r2_i = r_k^2
 * of its last k-nearest search. The host builds a BVH over the balls' boxes
 * (oclgi/accel/bvh_build.py; leaves index `balls`, the point ids in leaf
 * order). The changed impacts are read straight from the session's segment
 * store (segment.h): the impacts of each affected path's suffix, from its
 * first affected bounce on, exactly those pm_gather would gather (bounce 0
 * only with count_emitted). Called once before the re-trace (the old
 * impacts) and once after it (the new ones).
 *
 * pm_update_balls  one work-item per affected path; each impact of its
 *     suffix walks the BVH (box_bvh.h, the impact as a point box) and meets
 *     the balls of the leaves it lies in. Tests are pm_dist2 and
 *     pm_arrives_front, the very expressions of the k-nearest search, so a
 *     ball holds an impact here exactly when the search would rank it
 *     within r_k.
 *     mark = 0 (practical): sign * power is added to the sum of every point
 *         whose ball holds the impact, d2 < r2 (d2 <= r2 with include_kth:
 *         the k estimator sums the k-th too). The radius stays: the point's
 *         estimate becomes the fixed-radius one over the current impacts.
 *         Quantised as pm_finish does; -q is exact (round to nearest even
 *         is symmetric), so what leaves a sum is what entered it.
 *         Points with r2 = inf (fewer than k impacts) keep E = 0.
 *     mark = 1 (exact): every point whose closed ball (d2 <= r2) holds a
 *         changed impact may have new k nearest; it is listed once (marks
 *         guard against repeats) in `list`, its length in *n_listed. A point
 *         whose closed ball holds no changed impact keeps its k nearest: none
 *         of them left, and whatever arrived ranks after the k-th.
 * pm_unmark  clears the marks of the listed points (O(listed), not O(n)).
 */
#include "point_index.h"
#include "box_bvh.h"

__kernel void pm_update_balls(__global const BvhNode *nodes, __global const int *balls,
                              __global const float4 *qpos, __global const float4 *qnrm,
                              __global const float *r2, __global const Segment *segments, int max_depth,
                              __global const int *paths, __global const int *starts, int n_list,
                              int count_emitted, int front_only, int mark, int include_kth, float sign,
                              __global long *acc, __global int *marks, __global int *list,
                              __global int *n_listed)
{
    int k = get_global_id(0);
    if (k >= n_list) return;
    __global const Segment *path = segments + (size_t)paths[k] * max_depth;
    for (int b = max(starts[k], segment_first(count_emitted)); b < max_depth; ++b) {
        SegmentView s;
        if (!segment_read(path + b, &s)) {
            if (segment_is_hole(path + b)) continue;
            break; /* the path's end */
        }
        if (!segment_impact(path + b)) continue;
        float3 p = segment_end(&s), w = s.w;
        long3 q = (long3)(0);
        int have_q = 0;
        BoxBvhWalk walk;
        box_bvh_start(&walk);
        int leaf;
        while ((leaf = box_bvh_next_box(&walk, nodes, p, p)) >= 0) {
            int first = nodes[leaf].first, count = nodes[leaf].count;
            for (int j = first; j < first + count; ++j) {
                int i = balls[j];
                if (front_only && !pm_arrives_front(w, qnrm[i].xyz)) continue;
                float d2 = pm_dist2(p, qpos[i].xyz), r = r2[i];
                if (mark) {
                    if (d2 <= r && atomic_xchg(&marks[i], 1) == 0) list[atomic_inc(n_listed)] = i;
                    continue;
                }
                if (r == INFINITY || !(d2 < r || (include_kth && d2 == r))) continue;
                if (!have_q) { /* quantised once per impact, as pm_finish does */
                    q = segment_fixed_power(path + b);
                    if (sign < 0.0f) q = -q;
                    have_q = 1;
                }
                atom_add(acc + 3 * (size_t)i + 0, q.x);
                atom_add(acc + 3 * (size_t)i + 1, q.y);
                atom_add(acc + 3 * (size_t)i + 2, q.z);
            }
        }
    }
}

__kernel void pm_unmark(__global const int *list, int n, __global int *marks)
{
    int t = get_global_id(0);
    if (t < n) marks[list[t]] = 0;
}
