/* detp_disc_index.h: one segment against a BVH over DETP discs
 * (detp_disc_index.cl has the layout; update.cl walks the same tree while it
 * scans a session's store, light_reweight.cl to list a tail's discs).
 *
 * The tree: 8-wide BvhNode8 nodes (oclgi/estimators/detp_disc_index.py)
 * walked by box_wide.h, which reaches every leaf whose box the segment
 * meets; a leaf is a run of DiscBlocks [first, first + ceil(count / 8)) of
 * `count` discs.
 */
#ifndef OCLGI_DETP_DISC_INDEX_H
#define OCLGI_DETP_DISC_INDEX_H

#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "lane_bits.h"
#include "box_wide.h"

typedef BvhNode8 DiscNode;
typedef BoxWideWalk DiscWalk;
#define disc_walk_start box_wide_start

/* The next leaf the segment's part tmin <= t <= tmax meets: 1 and its
 * blocks' run, 0 when done. */
inline int disc_walk_next(DiscWalk *walk, __global const DiscNode *nodes, float3 o, float3 inv, float tmin,
                          float tmax, int *first, int *count)
{
    int leaf = ~box_wide_next_segment(walk, nodes, o, inv, tmin, tmax);
    if (leaf < 0) return 0; /* ~0: done */
    *first = leaf >> OCLGI_BOX_LEAF_BITS;
    *count = (leaf & ((1 << OCLGI_BOX_LEAF_BITS) - 1)) + 1;
    return 1;
}

/* The discs one segment (o, w, tmax = t_end + ext) crosses: every leaf of
 * the tree it meets, 8 discs at a time, each disc with its own squared
 * radius (DiscBlock r2); ON_HIT(id) runs once per crossed disc, in the
 * tree's order. `n_visited` and `n_tests` count nodes and disc tests. One walk
 * for every use (the sums here, light_reweight.cl's pair lists). */
#define DISC_INDEX_WALK(nodes, discs, o, w, tmax, n_visited, n_tests, ON_HIT)                          \
    DISC_INDEX_BLOCKS((nodes), (discs), (o), (w), 0.0f, (tmax), n_visited, n_tests,                       \
                      int8 hit_;                                                                          \
                      DETP_TEST(float8, hit_, b_->x, b_->y, b_->z, b_->nx, b_->ny, b_->nz, (o).x, (o).y,  \
                                (o).z, (w).x, (w).y, (w).z, (tmax), b_->r2);                              \
                      DISC_LANES(hit_, b_, ON_HIT);)

/* The walk itself: BODY (the variadic arguments) runs once per DiscBlock
 * `b_` of every leaf the part tmin <= t <= tmax of the segment meets
 * (box_wide.h). */
#define DISC_INDEX_BLOCKS(nodes, discs, o, w, tmin, tmax, n_visited, n_tests, ...)                     \
    do {                                                                                        \
        float3 inv_ = 1.0f / (w);                                                               \
        DiscWalk walk_;                                                                         \
        disc_walk_start(&walk_);                                                                \
        int first_, count_;                                                                     \
        while (disc_walk_next(&walk_, (nodes), (o), inv_, (tmin), (tmax), &first_, &count_)) {  \
            (n_tests) += (ulong)count_;                                                           \
            for (int blk_ = first_; blk_ < first_ + (count_ + OCLGI_LANES - 1) / OCLGI_LANES; ++blk_) { \
                __global const DiscBlock *b_ = (discs) + blk_;                                  \
                __VA_ARGS__                                                                     \
            }                                                                                   \
        }                                                                                       \
        (n_visited) += walk_.visited;                                                             \
    } while (0)

/* ON_HIT(id) for each lane of block b_ where hit (an int8) is set, lowest
 * lane first (lane_bits.h: one unpredictable branch per crossing instead
 * of one per lane; the listed pass in Sponza: 10.8 -> 10.4 ms). */
#define DISC_LANES(hit, b_, ON_HIT)                                                                \
    do {                                                                                          \
        uint m_ = lane_bits8(hit);                                                                \
        if (m_) {                                                                                 \
            int ids_[OCLGI_LANES];                                                                \
            vstore8((b_)->id, 0, ids_);                                                           \
            do {                                                                                  \
                int k_ = lowest_bit(m_);                                                          \
                m_ &= m_ - 1u;                                                                    \
                ON_HIT(ids_[k_]);                                                                 \
            } while (m_);                                                                         \
        }                                                                                         \
    } while (0)

/* The fixed-point power q added to disc `id`'s three sums. */
inline void disc_add(__global long *acc, int id, long3 q)
{
    __global long *a = acc + 3 * (size_t)id;
    atom_add(a + 0, q.x);
    atom_add(a + 1, q.y);
    atom_add(a + 2, q.z);
}

/* One segment (s, read from `slot`) against the tree, its fixed-point
 * power added to every disc it crosses (quantised once per segment that
 * crosses one, as detp_plain does), the first `cap` of those discs listed
 * in rec[0 ..] and all of them counted in *n (more than cap: the list is
 * incomplete, the caller does not keep it). */
inline void disc_index_segment_listed(__global const DiscNode *nodes, __global const DiscBlock *discs,
                                      __global const Segment *slot, const SegmentView *s, float ext,
                                      __global long *acc, __global int *rec, int cap, int *n, uint *visited,
                                      ulong *tests)
{
    float3 o = s->o, w = s->w;
    float tmax = s->t_end + ext; /* exactly as detp_plain */
    long3 q = 0;
    int have_q = 0;
#define DISC_INDEX_ADD(id)                               \
    do {                                                 \
        if (!have_q) { /* once per segment that hits */  \
            q = segment_fixed_power(slot);               \
            have_q = 1;                                  \
        }                                                \
        disc_add(acc, (id), q);                          \
        if (*n < cap) rec[*n] = (id);                    \
        ++*n;                                            \
    } while (0)
    DISC_INDEX_WALK(nodes, discs, o, w, tmax, *visited, *tests, DISC_INDEX_ADD);
#undef DISC_INDEX_ADD
}

/* The same, listing nothing. */
inline void disc_index_segment(__global const DiscNode *nodes, __global const DiscBlock *discs,
                               __global const Segment *slot, const SegmentView *s, float ext,
                               __global long *acc, uint *visited, ulong *tests)
{
    int n = 0;
    disc_index_segment_listed(nodes, discs, slot, s, ext, acc, 0, 0, &n, visited, tests);
}

/* A segment's listed crossings (disc_index_segment_listed, from an
 * earlier move) summed again with the segment's power as stored now: the
 * same discs a walk finds, without the walk. */
inline void disc_index_replay(__global const Segment *slot, __global const int *ids, int n, __global long *acc)
{
    if (n <= 0) return;
    long3 q = segment_fixed_power(slot);
    for (int j = 0; j < n; ++j) disc_add(acc, ids[j], q);
}

/* An update's old and new first segment of a re-traced suffix (so, sn),
 * which the caller found to share the origin and direction bit for bit,
 * with fixed-point powers q_old = -q_new (the subtraction's and the
 * addition's): only their lengths differ. Summing both would add q_old and
 * q_new to each disc both cross, which cancels exactly (integers), and one
 * of them to each disc only one crosses. The two DETP_TESTs differ in
 * num >= tmax wn alone, which holds for the larger tmax whenever it holds
 * for the smaller (wn < 0, rounding monotone), so a disc crossed by only
 * one has num < tmax_lo wn: its crossing t* = num / wn lies beyond
 * tmax_lo (1 - 2^-24), and, as for every accepted crossing (the pad
 * argument, estimators/detp_disc_index.py), inside the disc's box. The
 * walk takes t from tmax_lo (1 - 1e-4), far below any rounding of t*, to
 * tmax_hi, tests both lengths on the discs met and adds the one of a disc
 * crossed by one only: the sums of the full subtraction and addition, bit
 * for bit, without walking the common part. */
inline void disc_index_shared_first(__global const DiscNode *nodes, __global const DiscBlock *discs,
                                    const SegmentView *so, const SegmentView *sn, long3 q_old, long3 q_new,
                                    float ext, __global long *acc, uint *visited, ulong *tests)
{
    float3 o = sn->o, w = sn->w;
    float tmax_old = so->t_end + ext, tmax_new = sn->t_end + ext; /* exactly as the two walks */
    float tmax_hi = fmax(tmax_old, tmax_new);
    float tmin = fmin(tmax_old, tmax_new) * 0.9999f;
#define DISC_INDEX_ONE(id) disc_add(acc, (id), ho_[k_] ? q_old : q_new)
    DISC_INDEX_BLOCKS(nodes, discs, o, w, tmin, tmax_hi, *visited, *tests,
                      int8 hit_old_;
                      int8 hit_new_;
                      DETP_TEST(float8, hit_old_, b_->x, b_->y, b_->z, b_->nx, b_->ny, b_->nz, o.x, o.y, o.z,
                                w.x, w.y, w.z, tmax_old, b_->r2);
                      DETP_TEST(float8, hit_new_, b_->x, b_->y, b_->z, b_->nx, b_->ny, b_->nz, o.x, o.y, o.z,
                                w.x, w.y, w.z, tmax_new, b_->r2);
                      int8 one_ = hit_old_ ^ hit_new_;
                      if (any(one_)) {
                          int ho_[OCLGI_LANES];
                          vstore8(hit_old_, 0, ho_);
                          DISC_LANES(one_, b_, DISC_INDEX_ONE);
                      });
#undef DISC_INDEX_ONE
}

/* A path's segments from bounce `from` to its end (holes skipped) against
 * the tree, as disc_index_segment. With `cull`, a segment that misses the
 * box (lo, hi), which holds every disc's box (the tree's root box), is
 * skipped before the walk: box_slab is the walk's own test on a box that
 * holds every box the walk would test, so it keeps every segment the walk
 * could sum, and a rejected segment costs one scalar slab test instead of
 * a node's load, its 8-lane test and the stack. */
inline void disc_index_path_in(__global const DiscNode *nodes, __global const DiscBlock *discs,
                               __global const Segment *path, int from, int max_depth, float ext, int cull,
                               float3 lo, float3 hi, __global long *acc, uint *visited, ulong *tests)
{
    for (int b = from; b < max_depth; ++b) {
        SegmentView s;
        if (!segment_read(path + b, &s)) {
            if (segment_is_hole(path + b)) continue;
            break; /* the path's end */
        }
        float enter;
        if (cull && !box_slab(lo, hi, s.o, 1.0f / s.w, s.t_end + ext, &enter)) continue;
        disc_index_segment(nodes, discs, path + b, &s, ext, acc, visited, tests);
    }
}

#endif
