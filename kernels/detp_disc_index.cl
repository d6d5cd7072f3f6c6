/* detp_disc_index.cl: DETP with disc indexing (García 2006; DESIGN.md 3).
 *
 * detp_disc_index  one work-item per path of a batch (global size n_paths,
 *                  any local size), which walks its segments up to the
 *                  path's end (segment.h): reading only the stored
 *                  segments, not every slot, halves the cost of a pass over
 *                  a session's whole store. Each segment walks a BVH over the discs' boxes
 *                  (box_bvh.h); in every leaf it meets, it is tested against
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
 */
#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "work.h"
#include "detp_resolve.h"
#include "detp_disc_index.h"

__kernel void detp_disc_index(__global const DiscNode *nodes, __global const DiscBlock *discs,
                              __global const Segment *segments, int n_paths, int max_depth,
                              int count_emitted, float ext,
                              __global long *acc, __global ulong *work)
{
    int p = get_global_id(0);
    if (p >= n_paths) return;
    WORK_DECL;
    uint visited = 0;
    ulong tests = 0;
    __global const Segment *path = segments + (size_t)p * max_depth;
    for (int b = segment_first(count_emitted); b < max_depth; ++b) {
        SegmentView s;
        if (!segment_read(path + b, &s)) {
            if (segment_is_hole(path + b)) continue;
            break; /* the path's end */
        }
        disc_index_segment(nodes, discs, path + b, &s, ext, acc, &visited, &tests);
    }
    WORK_U(tests);
    WORK_NODE(visited);
    WORK_FLUSH(work);
}
