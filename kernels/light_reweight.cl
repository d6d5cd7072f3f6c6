/* light_reweight.cl: a light animation's frames as re-weightings of the
 * stored tails' contributions (driver: oclgi/tracing/light_reweight.py).
 *
 * Between frames of a light animation (light_reuse.cl) a stored path's tail
 * keeps its geometry; only one factor per path changes (reuse_path_frame's
 * scale). So which discs each tail segment crosses is found once:
 *
 * reweight_count  one work-item per stored path: the (disc, slot) pairs its
 *                 tail segments (bounce 1 on) make, by the disc index's walk
 *                 and DETP_TEST (the estimator's own test and extension);
 * reweight_fill   the same walk, the pairs written at the path's offset;
 * reweight_scales one work-item per stored path: frame j's factor of its
 *                 tail (0 where the frame sees nothing of it);
 * reweight_add    one work-item per pair: the slot's stored power times its
 *                 path's factor, quantised as the frame's segment would be
 *                 (segment_quantise of the same float product), added to
 *                 the disc's sums.
 *
 * A frame is then segment 0 of every path through the estimator plus one
 * pass over the pairs, and its sums equal the full frame's bit for bit.
 */
#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "detp_disc_index.h"
#include "light_reuse.h"

/* The walk over path i's tail, ON_PAIR(disc, slot) per crossing. */
#define REWEIGHT_TAIL(ON_PAIR)                                                   \
    do {                                                                         \
        __global const Segment *path_ = store + (size_t)i * max_depth;           \
        uint visited_ = 0;                                                       \
        ulong tests_ = 0;                                                        \
        for (int b = 1; b < max_depth; ++b) {                                    \
            SegmentView s_;                                                      \
            if (!segment_read(path_ + b, &s_)) {                                 \
                if (segment_is_hole(path_ + b)) continue;                        \
                break;                                                           \
            }                                                                    \
            float3 o_ = s_.o, w_ = s_.w;                                         \
            float tmax_ = s_.t_end + ext;                                        \
            int slot_ = i * max_depth + b;                                       \
            (void)slot_;                                                         \
            DISC_INDEX_WALK(nodes, discs, o_, w_, tmax_, visited_, tests_, ON_PAIR); \
        }                                                                        \
    } while (0)

__kernel void reweight_count(__global const DiscNode *nodes, __global const DiscBlock *discs,
                             __global const Segment *store, int n_paths, int max_depth, float ext,
                             __global int *counts)
{
    int i = get_global_id(0);
    if (i >= n_paths) return;
    int n = 0;
#define REWEIGHT_COUNT(id) (++n)
    REWEIGHT_TAIL(REWEIGHT_COUNT);
#undef REWEIGHT_COUNT
    counts[i] = n;
}

__kernel void reweight_fill(__global const DiscNode *nodes, __global const DiscBlock *discs,
                            __global const Segment *store, int n_paths, int max_depth, float ext,
                            __global const long *offsets, __global int *pair_disc, __global int *pair_slot)
{
    int i = get_global_id(0);
    if (i >= n_paths) return;
    long at = offsets[i];
#define REWEIGHT_WRITE(id)          \
    do {                            \
        pair_disc[at] = (id);       \
        pair_slot[at] = slot_;      \
        ++at;                       \
    } while (0)
    REWEIGHT_TAIL(REWEIGHT_WRITE);
#undef REWEIGHT_WRITE
}

__kernel void reweight_scales(__global const float4 *tri_normals, __global const Emitter *lights,
                              __global const float *table, int frame, int paths_per_position,
                              __global const Segment *store, __global const float *density_sum,
                              __global const uint *visible, int words_per_path, int n_paths, int max_depth,
                              __global float *scales)
{
    int i = get_global_id(0);
    if (i >= n_paths) return;
    float3 d;
    float r, c, scale;
    int tri;
    if (!reuse_path_frame(tri_normals, lights, table, frame, paths_per_position, &store[(size_t)i * max_depth],
                          density_sum[i], reuse_seen(visible, words_per_path, i, frame), &d, &r, &tri, &c, &scale))
        scale = 0.0f;
    scales[i] = scale;
}

__kernel void reweight_add(__global const Segment *store, int max_depth, __global const int *pair_disc,
                           __global const int *pair_slot, long n_pairs, __global const float *scales,
                           __global long *acc)
{
    long k = get_global_id(0);
    if (k >= n_pairs) return;
    int slot = pair_slot[k];
    long3 q = segment_quantise(segment_power(store + slot) * scales[slot / max_depth]);
    __global long *a = acc + 3 * (size_t)pair_disc[k];
    atom_add(a + 0, q.x);
    atom_add(a + 1, q.y);
    atom_add(a + 2, q.z);
}
