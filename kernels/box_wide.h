/* box_wide.h: walking an 8-wide BVH over boxes (the disc index's) for
 * overlap queries.
 *
 * The tree is a binary overlap tree (BvhNode) collapsed into BvhNode8
 * records (oclgi_types.h; oclgi/accel/box_wide.py): the 8 child boxes of a
 * node in SoA float8 fields, so one float8 slab test meets all 8 children.
 * A lane's child is the index of an inner child's node (> 0), a leaf's
 * ~(first << OCLGI_BOX_LEAF_BITS | (count - 1)) (< 0), or 0 for an unused
 * lane (no node's child is the root). An overlap query needs EVERY leaf it
 * meets, in any order, so each child met is pushed, leaves included, and
 * a popped leaf is returned.
 *
 * Use as an iterator, as box_bvh.h:
 *
 *     BoxWideWalk walk;
 *     box_wide_start(&walk);
 *     int leaf;
 *     while ((leaf = box_wide_next_segment(&walk, nodes, o, inv, 0.0f, tmax)) < 0) { ~leaf ... }
 *     WORK_NODE(walk.visited);
 *
 * `visited` counts wide nodes whose 8 child boxes were tested (the root
 * included): one float8 slab test each, where a binary walk counts one box
 * per node.
 *
 * Conservative: each lane runs box_slab's (box.h) operations in the same
 * order, so a lane accepts exactly what box_slab accepts for that box, and
 * a node's lanes are binary nodes' boxes bit for bit. A leaf's wide
 * ancestors are some of its binary ancestors, so every leaf a binary walk
 * (box_slab per node) reaches this one reaches too (and tests the same
 * leaf box): nothing DETP_TEST accepts is culled.
 */
#ifndef OCLGI_BOX_WIDE_H
#define OCLGI_BOX_WIDE_H

#include "oclgi_types.h"
#include "box.h"
#include "lane_bits.h"

typedef struct {
    int stack[OCLGI_BOX_WIDE_STACK]; /* node indices (>= 0) and leaves (< 0) */
    int sp;
    uint visited;
} BoxWideWalk;

inline void box_wide_start(BoxWideWalk *walk)
{
    walk->stack[0] = 0; /* the root */
    walk->sp = 1;
    walk->visited = 0;
}

/* box_slab (box.h) on the node's 8 child boxes at once: lane k is -1 when
 * the segment o + t w, tmin <= t <= tmax, meets child k's box. With tmin =
 * 0 the operations are box_slab's; a tmin > 0 only raises the entry (the
 * part of a segment a query can skip, detp_disc_index.h). */
inline int8 box8_meets_segment(__global const BvhNode8 *n, float3 o, float3 inv, float tmin, float tmax)
{
    float8 t0x = (n->lox - o.x) * inv.x, t1x = (n->hix - o.x) * inv.x;
    float8 t0y = (n->loy - o.y) * inv.y, t1y = (n->hiy - o.y) * inv.y;
    float8 t0z = (n->loz - o.z) * inv.z, t1z = (n->hiz - o.z) * inv.z;
    float8 e = fmax(fmax(fmin(t0x, t1x), fmin(t0y, t1y)), fmax(fmin(t0z, t1z), (float8)(tmin)));
    float8 leave = fmin(fmin(fmax(t0x, t1x), fmax(t0y, t1y)), fmin(fmax(t0z, t1z), (float8)(tmax))) * 1.0000004f;
    return e <= leave;
}

/* The next leaf the segment (tmin <= t <= tmax) meets, as its lane value
 * ~(first << BITS | count - 1) (< 0); 0 when done. */
inline int box_wide_next_segment(BoxWideWalk *walk, __global const BvhNode8 *nodes, float3 o, float3 inv,
                                 float tmin, float tmax)
{
    while (walk->sp > 0) {
        int c = walk->stack[--walk->sp];
        if (c < 0) return c;
        __global const BvhNode8 *n = &nodes[c];
        walk->visited++;
        int8 child = n->child;
        int8 hit = box8_meets_segment(n, o, inv, tmin, tmax) & (child != 0);
        if (!any(hit)) continue;
        int ch[OCLGI_LANES];
        vstore8(child, 0, ch);
        /* The lanes hit pushed lowest first (lane_bits.h; the order of the
         * branch-free compaction this replaced, which wrote all 8 lanes
         * through a chain of stack-pointer updates: Sponza's change pass
         * 22.0 -> 21.1 ms, its listed pass 9.4 -> 8.7 ms). */
        uint m = lane_bits8(hit);
        int sp = walk->sp;
        do {
            walk->stack[sp++] = ch[lowest_bit(m)];
            m &= m - 1u;
        } while (m);
        walk->sp = sp;
    }
    return 0;
}

#endif
