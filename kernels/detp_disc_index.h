/* detp_disc_index.h: one segment against a BVH over DETP discs
 * (detp_disc_index.cl has the layout; update.cl walks the same tree while it
 * scans a session's store, light_reweight.cl to list a tail's discs).
 *
 * The tree (oclgi/estimators/detp_disc_index.py ``tree``): 8-wide BvhNode8
 * nodes walked by box_wide.h, or, built with OCLGI_DISC_TREE_BINARY, the
 * binary BvhNode tree walked by box_bvh.h (kept to measure one against the
 * other). Both reach every leaf whose box the segment meets; a leaf is a
 * run of DiscBlocks [first, first + ceil(count / 8)) of `count` discs.
 */
#ifndef OCLGI_DETP_DISC_INDEX_H
#define OCLGI_DETP_DISC_INDEX_H

#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"

#ifdef OCLGI_DISC_TREE_BINARY
#include "box_bvh.h"
typedef BvhNode DiscNode;
typedef BoxBvhWalk DiscWalk;
#define disc_walk_start box_bvh_start

/* The next leaf the segment meets: 1 and its blocks' run, 0 when done. */
inline int disc_walk_next(DiscWalk *walk, __global const DiscNode *nodes, float3 o, float3 inv, float tmax,
                          int *first, int *count)
{
    int leaf = box_bvh_next_segment(walk, nodes, o, inv, tmax);
    if (leaf < 0) return 0;
    *first = nodes[leaf].first;
    *count = nodes[leaf].count;
    return 1;
}
#else
#include "box_wide.h"
typedef BvhNode8 DiscNode;
typedef BoxWideWalk DiscWalk;
#define disc_walk_start box_wide_start

inline int disc_walk_next(DiscWalk *walk, __global const DiscNode *nodes, float3 o, float3 inv, float tmax,
                          int *first, int *count)
{
    int leaf = ~box_wide_next_segment(walk, nodes, o, inv, tmax);
    if (leaf < 0) return 0; /* ~0: done */
    *first = leaf >> OCLGI_BOX_LEAF_BITS;
    *count = (leaf & ((1 << OCLGI_BOX_LEAF_BITS) - 1)) + 1;
    return 1;
}
#endif

/* The discs one segment (o, w, tmax = t_end + ext) crosses: every leaf of
 * the tree it meets, 8 discs at a time, each disc with its own squared
 * radius (DiscBlock r2); ON_HIT(id) runs once per crossed disc, in the
 * tree's order. `n_visited` and `n_tests` count nodes and disc tests. One walk
 * for every use (the sums here, light_reweight.cl's pair lists). */
#define DISC_INDEX_WALK(nodes, discs, o, w, tmax, n_visited, n_tests, ON_HIT)                          \
    do {                                                                                        \
        float3 inv_ = 1.0f / (w);                                                               \
        DiscWalk walk_;                                                                         \
        disc_walk_start(&walk_);                                                                \
        int first_, count_;                                                                     \
        while (disc_walk_next(&walk_, (nodes), (o), inv_, (tmax), &first_, &count_)) {          \
            (n_tests) += (ulong)count_;                                                           \
            for (int blk_ = first_; blk_ < first_ + (count_ + OCLGI_LANES - 1) / OCLGI_LANES; ++blk_) { \
                __global const DiscBlock *b_ = (discs) + blk_;                                  \
                int8 hit_;                                                                      \
                DETP_TEST(float8, hit_, b_->x, b_->y, b_->z, b_->nx, b_->ny, b_->nz, (o).x, (o).y, (o).z, \
                          (w).x, (w).y, (w).z, (tmax), b_->r2);                                 \
                if (!any(hit_)) continue;                                                       \
                int ids_[OCLGI_LANES], h_[OCLGI_LANES];                                          \
                vstore8(b_->id, 0, ids_);                                                       \
                vstore8(hit_, 0, h_);                                                           \
                for (int k_ = 0; k_ < OCLGI_LANES; ++k_) {                                      \
                    if (!h_[k_]) continue;                                                      \
                    ON_HIT(ids_[k_]);                                                           \
                }                                                                               \
            }                                                                                   \
        }                                                                                       \
        (n_visited) += walk_.visited;                                                             \
    } while (0)

/* One segment (s, read from `slot`) against the tree, its fixed-point
 * power added to every disc it crosses (quantised once per segment that
 * crosses one, as detp_plain does). */
inline void disc_index_segment(__global const DiscNode *nodes, __global const DiscBlock *discs,
                               __global const Segment *slot, const SegmentView *s, float ext,
                               __global long *acc, uint *visited, ulong *tests)
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
        __global long *a_ = acc + 3 * (size_t)(id);      \
        atom_add(a_ + 0, q.x);                           \
        atom_add(a_ + 1, q.y);                           \
        atom_add(a_ + 2, q.z);                           \
    } while (0)
    DISC_INDEX_WALK(nodes, discs, o, w, tmax, *visited, *tests, DISC_INDEX_ADD);
#undef DISC_INDEX_ADD
}

#endif
