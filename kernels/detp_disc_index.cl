/* detp_disc_index.cl: DETP with disc indexing (García 2006; DESIGN.md 3).
 *
 * detp_disc_index  one work-item per path of a batch (global size n_paths,
 *                  any local size), or per path of `list` (when it is
 *                  not NULL: list[i] is the i-th path), which walks its segments up to the
 *                  path's end (segment.h): reading only the stored
 *                  segments, not every slot, halves the cost of a pass over
 *                  a session's whole store. Each segment walks a BVH over the discs' boxes
 *                  (box_wide.h); in every leaf it meets, it is tested against
 *                  the leaf's discs 8 at a time (float8 lanes, as detp_plain)
 *                  with DETP_TEST (detp.h), and its fixed-point power is
 *                  added to each disc it crosses with 64-bit atom_add:
 *                  work-items share discs, and integer atomics keep the sums
 *                  independent of order. Counts u = segment-disc tests (real
 *                  discs of each leaf met) and BVH nodes visited (work.h).
 *
 * Disc blocks (host: oclgi/estimators/detp_disc_index.py): the discs of a
 * leaf are stored as ceil(count / 8) DiscBlocks (oclgi_types.h: x, y, z,
 * nx, ny, nz, squared radius, point id, a float8 or int8 each); padding lanes have a zero
 * normal, which never passes DETP_TEST (w.n = 0). A leaf node's `first` is
 * its first block and `count` its number of real discs.
 *
 * count_emitted = 0 skips segments leaving the light (bounce 0), as detp.cl.
 *
 * detp_disc_index_change  (below) a move's subtraction and addition in one
 *                  pass, the common part of each suffix's first segment
 *                  skipped.
 *
 * With `cull`, a segment that misses (root_lo, root_hi), the tree's root
 * box, is skipped before the walk (disc_index_path_in): a camera session's
 * dynamic points, summed over the paths whose cell masks meet their discs'
 * box (update.cl update_candidates), whose segments mostly pass the cells
 * but not the box (14.4 to 12.6 ms a move in Sponza, 4.8 to 3.6 in the
 * Cornell box). A whole batch against the static points' tree, whose box
 * is the scene's, passes cull = 0.
 */
#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "work.h"
#include "detp_resolve.h"
#include "detp_disc_index.h"
#include "prefetch.h"

__kernel void detp_disc_index(__global const DiscNode *nodes, __global const DiscBlock *discs,
                              __global const Segment *segments, __global const int *list, int n_paths,
                              int max_depth, int count_emitted, float ext, int cull, float4 root_lo,
                              float4 root_hi, __global long *acc, __global ulong *work)
{
    int i = get_global_id(0);
    if (i >= n_paths) return;
    int p = list ? list[i] : i;
    prefetch_listed_path(segments, list, i, n_paths, max_depth, 3);
    WORK_DECL;
    uint visited = 0;
    ulong tests = 0;
    disc_index_path_in(nodes, discs, segments + (size_t)p * max_depth, segment_first(count_emitted), max_depth,
                       ext, cull, root_lo.xyz, root_hi.xyz, acc, &visited, &tests);
    WORK_U(tests);
    WORK_NODE(visited);
    WORK_FLUSH(work);
}

/* Both halves of a move's update at once, after the re-trace: one
 * work-item per re-traced path k, with its old suffix (gathered before the
 * re-trace, power times -1, kernels/update.cl update_gather) and its new
 * one (the store's path paths[k] from starts[k] on). Each segment of either
 * is summed as detp_disc_index sums it, but the suffixes' first segments:
 * a re-trace starts from the same state (photon_trace.cl photon_retrace),
 * so they share origin, direction and power and differ in length only;
 * when the bits say so, disc_index_shared_first adds just their
 * difference. The sums equal a subtraction pass plus an addition pass bit
 * for bit (tests/test_session.py compares the two).
 *
 * With generation >= 0 (the store's re-trace count, after this move's),
 * the discs each new segment crosses are listed for the next move: run
 * (offset into ids, count) per slot k * max_depth + b, the ids in the
 * path's own `cap` entries of `ids` (a segment whose discs do not fit, or
 * the shared first segment, gets count -1: not listed), and
 * crossed_at[path] = (generation, k). A path the last move re-traced
 * (crossed_at = (generation - 1, k')) finds the segments its old suffix
 * holds listed in prev_runs / prev_ids and sums them from the lists: a
 * walk would find the same discs (the segment has not changed since),
 * and the old power is exactly the negated new one. Most of a small
 * object's re-traced paths are re-traced again on the next move (Sponza:
 * 78% of the old suffixes' segments). replayed[0] counts the segments
 * summed from lists. */
__kernel void detp_disc_index_change(__global const DiscNode *nodes, __global const DiscBlock *discs,
                                     __global const Segment *old_suffixes, __global const Segment *store,
                                     __global const int *paths, __global const int *starts, int n_list,
                                     int max_depth, int count_emitted, float ext,
                                     __global long *acc, __global ulong *work,
                                     __global int2 *crossed_at, int generation,
                                     __global const int2 *prev_runs, __global const int *prev_ids,
                                     __global int2 *runs, __global int *ids, int cap,
                                     __global ulong *replayed)
{
    int k = get_global_id(0);
    if (k >= n_list) return;
    prefetch_listed_path(store, paths, k, n_list, max_depth, 3);
    WORK_DECL;
    uint visited = 0;
    ulong tests = 0;
    int p = paths[k];
    __global const Segment *old = old_suffixes + (size_t)k * max_depth;
    __global const Segment *cur = store + (size_t)p * max_depth;
    int b0 = starts[k];
    int from = max(b0, segment_first(count_emitted));
    int last = -1; /* the path's entry of the last move, if it listed this path */
    if (generation >= 0) {
        int2 at = crossed_at[p];
        if (at.x == generation - 1) last = at.y;
    }
    SegmentView so, sn;
    if (from == b0 && segment_read(old + b0, &so) && segment_read(cur + b0, &sn) &&
        all(as_uint3(so.o) == as_uint3(sn.o)) && all(as_uint3(so.w) == as_uint3(sn.w))) {
        long3 q_old = segment_fixed_power(old + b0), q_new = segment_fixed_power(cur + b0);
        if (all(q_old == -q_new)) {
            disc_index_shared_first(nodes, discs, &so, &sn, q_old, q_new, ext, acc, &visited, &tests);
            from = b0 + 1;
        }
    }
    /* the old suffix, from the last move's lists where it has them (none
     * without generation), else walked */
    uint n_replayed = 0;
    for (int b = from; b < max_depth; ++b) {
        SegmentView s;
        if (!segment_read(old + b, &s)) {
            if (segment_is_hole(old + b)) continue;
            break; /* the path's end */
        }
        int2 run = last >= 0 ? prev_runs[(size_t)last * max_depth + b] : (int2)(0, -1);
        if (run.y >= 0) {
            disc_index_replay(old + b, prev_ids + run.x, run.y, acc);
            ++n_replayed;
        } else {
            disc_index_segment(nodes, discs, old + b, &s, ext, acc, &visited, &tests);
        }
    }
    /* the new suffix, walked, and listed with generation (cap is 0 without) */
    __global int2 *mine = generation >= 0 ? runs + (size_t)k * max_depth : 0;
    size_t base = (size_t)k * cap;
    int used = 0, b = 0;
    for (; mine && b < from; ++b) mine[b] = (int2)(0, -1);
    for (b = from; b < max_depth; ++b) {
        SegmentView s;
        if (!segment_read(cur + b, &s)) {
            if (mine) mine[b] = (int2)(0, -1);
            if (segment_is_hole(cur + b)) continue;
            break;
        }
        int n = 0;
        disc_index_segment_listed(nodes, discs, cur + b, &s, ext, acc, ids + base + used, cap - used, &n,
                                  &visited, &tests);
        if (!mine) continue;
        if (n <= cap - used) {
            mine[b] = (int2)((int)(base + used), n);
            used += n;
        } else { /* did not fit: this segment and the path's later ones go unlisted */
            mine[b] = (int2)(0, -1);
            used = cap;
        }
    }
    if (mine) {
        for (; b < max_depth; ++b) mine[b] = (int2)(0, -1);
        crossed_at[p] = (int2)(generation, k);
    }
    if (n_replayed) atom_add(replayed, (ulong)n_replayed); /* segments summed from lists (a count) */
    WORK_U(tests);
    WORK_NODE(visited);
    WORK_FLUSH(work);
}
