/* detp_disc_index.h: one segment against a BVH over DETP discs
 * (detp_disc_index.cl has the layout; update.cl walks the same tree while it
 * scans a session's store).
 */
#ifndef OCLGI_DETP_DISC_INDEX_H
#define OCLGI_DETP_DISC_INDEX_H

#include "oclgi_types.h"
#include "segment.h"
#include "detp.h"
#include "box_bvh.h"

/* One segment (s, read from `slot`) against the tree: every leaf it meets,
 * 8 discs at a time, each disc with its own squared radius (DiscBlock r2). */
inline void disc_index_segment(__global const BvhNode *nodes, __global const DiscBlock *discs,
                               __global const Segment *slot, const SegmentView *s, float ext,
                               __global long *acc, uint *visited, ulong *tests)
{
    float3 o = s->o, w = s->w;
    float tmax = s->t_end + ext; /* exactly as detp_plain */
    float3 inv = 1.0f / w;
    long3 q = 0;
    int have_q = 0;
    BoxBvhWalk walk;
    box_bvh_start(&walk);
    int leaf;
    while ((leaf = box_bvh_next_segment(&walk, nodes, o, inv, tmax)) >= 0) {
        int count = nodes[leaf].count;
        int first = nodes[leaf].first;
        *tests += (ulong)count;
        for (int blk = first; blk < first + (count + OCLGI_LANES - 1) / OCLGI_LANES; ++blk) {
            __global const DiscBlock *b = discs + blk;
            int8 hit;
            DETP_TEST(float8, hit, b->x, b->y, b->z, b->nx, b->ny, b->nz, o.x, o.y, o.z, w.x, w.y, w.z,
                      tmax, b->r2);
            if (!any(hit)) continue;
            if (!have_q) { /* quantised once per segment, as detp_plain does */
                q = segment_fixed_power(slot);
                have_q = 1;
            }
            int ids[OCLGI_LANES], h[OCLGI_LANES];
            vstore8(b->id, 0, ids);
            vstore8(hit, 0, h);
            for (int k = 0; k < OCLGI_LANES; ++k) {
                if (!h[k]) continue;
                __global long *a = acc + 3 * (size_t)ids[k];
                atom_add(a + 0, q.x);
                atom_add(a + 1, q.y);
                atom_add(a + 2, q.z);
            }
        }
    }
    *visited += walk.visited;
}

#endif
