/* detp_ray_map.cl: DETP with a ray map (Havran et al. 2005; DESIGN.md 3).
 *
 * detp_ray_map  one work-item per disc that can be crossed (n_discs, any
 *               local size; the host orders them in Morton order so that
 *               neighbouring work-items walk the same nodes). The disc's
 *               padded box walks a BVH over the boxes of the batch's segment
 *               pieces (box_bvh.h); the pieces of every leaf met are tested
 *               8 at a time (float8 lanes) with DETP_TEST (detp.h) and
 *               their claim range, and the fixed-point power of each
 *               crossing segment is added to the disc's private sums. A
 *               work-item owns its disc, so the sums go to memory with plain
 *               adds; batches run in order.
 *               Counts u = segment-disc tests (real pieces of each leaf met)
 *               and BVH nodes visited (work.h).
 *
 * Piece blocks (host: oclgi/estimators/detp_ray_map.py): the pieces of a
 * leaf are stored as ceil(count / 8) PieceBlocks (oclgi_types.h: ox, oy,
 * oz, wx, wy, wz, t_end of the whole segment, slot, claim_lo, claim_hi, a
 * float8 or int8 each). Padding lanes have w = 0, which never passes
 * DETP_TEST (w.n = 0). A leaf node's `first` is its first block, `count`
 * its number of real pieces. The power is read from the batch's segment
 * store by slot, only for crossing segments.
 *
 * Discs: a RayMapDisc each (oclgi_types.h): centre, point id, normal,
 * padded box.
 */
#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "work.h"
#include "detp_resolve.h"
#include "box_bvh.h"

__kernel void detp_ray_map(__global const BvhNode *nodes, __global const PieceBlock *blocks,
                           __global const RayMapDisc *discs, int n_discs, __global const Segment *segments,
                           float radius2, float ext, __global long *acc,
                           __global ulong *work)
{
    int i = get_global_id(0);
    if (i >= n_discs) return;
    WORK_DECL;
    __global const RayMapDisc *disc = discs + i;
    float3 x = vload3(0, disc->x), n = vload3(0, disc->n);
    float3 lo = vload3(0, disc->lo), hi = vload3(0, disc->hi);
    long3 sum = 0;
    BoxBvhWalk walk;
    box_bvh_start(&walk);
    int leaf;
    while ((leaf = box_bvh_next_box(&walk, nodes, lo, hi)) >= 0) {
        int count = nodes[leaf].count;
        int first = nodes[leaf].first;
        WORK_U(count);
        for (int blk = first; blk < first + (count + OCLGI_LANES - 1) / OCLGI_LANES; ++blk) {
            __global const PieceBlock *b = blocks + blk;
            float8 tmax = b->t_end + ext; /* per lane, exactly as detp_plain's t_end + ext */
            int8 hit;
            DETP_TEST(float8, hit, x.x, x.y, x.z, n.x, n.y, n.z, b->ox, b->oy, b->oz, b->wx, b->wy, b->wz,
                      tmax, radius2);
            if (!any(hit)) continue;
            /* A segment cut into pieces is in the map once per piece; only
             * the piece whose claim range holds the crossing parameter
             * counts it. Every piece keeps the whole segment's o and w, so
             * all compute the same t, and the ranges partition the line:
             * exactly one piece counts a crossing. */
            float8 wn = b->wx * n.x + b->wy * n.y + b->wz * n.z;
            float8 num = (x.x - b->ox) * n.x + (x.y - b->oy) * n.y + (x.z - b->oz) * n.z;
            float8 t = num / wn;
            hit &= (t >= b->claim_lo) & (t < b->claim_hi);
            if (!any(hit)) continue;
            int slots[OCLGI_LANES], h[OCLGI_LANES];
            vstore8(b->slot, 0, slots);
            vstore8(hit, 0, h);
            for (int k = 0; k < OCLGI_LANES; ++k)
                if (h[k]) sum += segment_fixed_power(segments + slots[k]);
        }
    }
    int id = disc->id;
    acc[3 * (size_t)id + 0] += sum.x;
    acc[3 * (size_t)id + 1] += sum.y;
    acc[3 * (size_t)id + 2] += sum.z;
    WORK_NODE(walk.visited);
    WORK_FLUSH(work);
}
