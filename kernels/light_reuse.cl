/* light_reuse.cl: moving point and spot lights by path reuse (Sbert,
 * Szecsi and Szirmay-Kalos 2004); the derivation is in
 * oclgi/tracing/light_reuse.py.
 *
 * The store holds F x n paths traced by photon_trace.cl, path id k n + i
 * from light position k (record k of `lights`, one Emitter per position).
 * Only their first hit x (the end of segment 0) and their tails (segments
 * 1..) are reused.
 *
 * reuse_weights  one work-item per stored path: the area density p_l(x) of
 *                every position l producing this first hit, arriving on
 *                the side the tail leaves from; their sum D, and one
 *                visibility bit per position (the shadow rays, F - 1 per path,
 *                traced once for the whole animation).
 * reuse_frame    one work-item per stored path: the path as frame j sees
 *                it, segment 0 from light position j to x, the tail's
 *                powers scaled, written path-major into a batch for any
 *                estimator. No ray is traced: visibility is the bit.
 *
 * Both kernels compute p_j(x) with reuse_density from the same floats in
 * the same order, so the weight p_j / D is the same whichever kernel or
 * batch computes it, and frames are bit-exact whatever the split.
 */
#include "light_reuse.h"

/* visible: words_per_path uints per path, bit l of word l / 32 for position l. */
__kernel void reuse_weights(SCENE_ARGS, __global const float4 *tri_normals, __global const Emitter *lights,
                            __global const float *table, int n_positions, int paths_per_position,
                            __global const Segment *store,
                            int n_paths, int max_depth, float eps, int words_per_path,
                            __global float *density_sum, __global uint *visible)
{
    int i = get_global_id(0);
    if (i >= n_paths) return;
    __global uint *bits = &visible[(size_t)i * words_per_path];
    for (int w = 0; w < words_per_path; ++w) bits[w] = 0u;
    float3 x, n;
    float side;
    int tri;
    float sum = 0.0f;
    if (reuse_first_hit(&store[(size_t)i * max_depth], tri_normals, &x, &n, &side, &tri)) {
        /* the path's own position saw x: it hit it (no shadow ray, so no
         * grazing miss of one either) */
        int own = store[(size_t)i * max_depth].path / paths_per_position;
        for (int l = 0; l < n_positions; ++l) { /* in order: the float sum is the same everywhere */
            float3 d;
            float r;
            float p = reuse_density(&lights[l], table, x, n, side, &d, &r);
            if (p > 0.0f && (l == own || reuse_visible(SCENE_PASS, &lights[l], d, r, eps))) {
                sum += p;
                bits[l >> 5] |= 1u << (l & 31);
            }
        }
    }
    density_sum[i] = sum;
}

/* Frame j's version of stored paths first .. first + count - 1, into
 * slots (i - first) * max_depth + b of `out`. Powers (units of phi_max):
 * segment 0 carries the light's record power times its profile towards x
 * times w = p_j / D; the tail's stored powers are scaled by the same
 * factor over the profile the path was traced with. w <= 1, so every
 * power stays <= 1 (oclgi/tracing/light_reuse.py: the F of the balance
 * heuristic goes into the resolve's photon count). tails = 0 writes
 * segment 0 alone (the direct light: what an estimator that re-weights
 * the tails' stored contributions would still have to estimate). */
__kernel void reuse_frame(__global const float4 *tri_normals, __global const Emitter *lights,
                          __global const float *table, int frame, int paths_per_position, int tails,
                          __global const Segment *store, __global const int *store_len,
                          __global const float *density_sum, __global const uint *visible, int words_per_path,
                          int first, int count, int max_depth, __global Segment *out, __global int *out_len)
{
    int k = get_global_id(0);
    if (k >= count) return;
    int i = first + k;
    __global const Segment *src = &store[(size_t)i * max_depth];
    __global Segment *dst = &out[(size_t)k * max_depth];
    int path = src->path;
    float3 d;
    float r, c, scale;
    int tri;
    if (!reuse_path_frame(tri_normals, lights, table, frame, paths_per_position, src, density_sum[i],
                          reuse_seen(visible, words_per_path, i, frame), &d, &r, &tri, &c, &scale)) {
        for (int b = 0; b < max_depth; ++b) segment_write_empty(&dst[b], path);
        out_len[k] = 0;
        return;
    }
    __global const Emitter *em = &lights[frame];
    segment_write(&dst[0], vload3(0, em->p), r, d, tri, vload3(0, em->power) * c, path);
    int len = tails ? store_len[i] : 1;
    for (int b = 1; b < max_depth; ++b) {
        if (b >= len) {
            segment_write_empty(&dst[b], path);
            continue;
        }
        Segment seg = src[b];
        seg.power[0] *= scale;
        seg.power[1] *= scale;
        seg.power[2] *= scale;
        dst[b] = seg;
    }
    out_len[k] = len;
}
