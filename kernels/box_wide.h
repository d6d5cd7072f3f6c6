/* box_wide.h: walking an 8-wide BVH over boxes (the disc index's) for
 * overlap queries.
 *
 * The tree is a binary overlap tree (box_bvh.h) collapsed into BvhNode8
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
 * included): one float8 slab test each, where box_bvh.h counts one box per
 * node.
 *
 * Conservative, like box_bvh.h: each lane runs box_slab's (box.h)
 * operations in the same order, so a lane accepts exactly what box_slab
 * accepts for that box, and a node's lanes are binary nodes' boxes bit for
 * bit. A leaf's wide ancestors are some of its binary ancestors, so every
 * leaf the binary walk reaches this one reaches too (and tests the same
 * leaf box): nothing DETP_TEST accepts is culled.
 */
#ifndef OCLGI_BOX_WIDE_H
#define OCLGI_BOX_WIDE_H

#include "oclgi_types.h"
#include "box.h"

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

/* Inlined into every walk: called as a function, the walk's state went
 * through memory, and each push below waited on the stack pointer's last
 * store (a fifth of the disc index's node time under perf). */
#define BOX_WIDE_INLINE inline __attribute__((always_inline))

/* box_slab (box.h) on the node's 8 child boxes at once: lane k is -1 when
 * the segment o + t w, tmin <= t <= tmax, meets child k's box. With tmin =
 * 0 the operations are box_slab's; a tmin > 0 only raises the entry (the
 * part of a segment a query can skip, detp_disc_index.h).
 *
 * `finite`: every 1/w is finite; then (lo - o) * inv and (hi - o) * inv
 * are never NaN for a used lane's finite planes and are ordered by the sign
 * of inv alone (rounding is monotone), so taking the near plane's product
 * as the entry and the far one's as the exit gives fmin's and fmax's
 * values, up to the sign of a zero, which no comparison below sees: the
 * same lanes meet, with half the min/max operations (bvh.h does the same).
 * An unused lane (child 0, planes +inf) may then give anything: the walk
 * masks it. Otherwise box_slab's NaN-dropping form is used. */
BOX_WIDE_INLINE int8 box8_meets_segment(__global const BvhNode8 *n, int finite, int3 near, float3 o, float3 inv,
                                        float tmin, float tmax)
{
    if (finite) {
        __global const float8 *f = &n->lox;
        float8 t0x = (f[near.x] - o.x) * inv.x, t1x = (f[3 - near.x] - o.x) * inv.x;
        float8 t0y = (f[near.y] - o.y) * inv.y, t1y = (f[5 - near.y] - o.y) * inv.y;
        float8 t0z = (f[near.z] - o.z) * inv.z, t1z = (f[7 - near.z] - o.z) * inv.z;
        float8 e = max(max(t0x, t0y), max(t0z, (float8)(tmin)));
        float8 leave = min(min(t1x, t1y), min(t1z, (float8)(tmax))) * 1.0000004f;
        return e <= leave;
    }
    float8 t0x = (n->lox - o.x) * inv.x, t1x = (n->hix - o.x) * inv.x;
    float8 t0y = (n->loy - o.y) * inv.y, t1y = (n->hiy - o.y) * inv.y;
    float8 t0z = (n->loz - o.z) * inv.z, t1z = (n->hiz - o.z) * inv.z;
    float8 e = fmax(fmax(fmin(t0x, t1x), fmin(t0y, t1y)), fmax(fmin(t0z, t1z), (float8)(tmin)));
    float8 leave = fmin(fmin(fmax(t0x, t1x), fmax(t0y, t1y)), fmin(fmax(t0z, t1z), (float8)(tmax))) * 1.0000004f;
    return e <= leave;
}

/* The next leaf the segment (tmin <= t <= tmax) meets, as its lane value
 * ~(first << BITS | count - 1) (< 0); 0 when done. The stack pointer and
 * the count live in registers for the whole step. */
BOX_WIDE_INLINE int box_wide_next_segment(BoxWideWalk *walk, __global const BvhNode8 *nodes, float3 o, float3 inv,
                                          float tmin, float tmax)
{
    int finite = isfinite(inv.x) && isfinite(inv.y) && isfinite(inv.z);
    /* the near planes' field indices (lo x..z = 0..2, hi x..z = 3..5) */
    int3 near = (int3)(inv.x >= 0.0f ? 0 : 3, inv.y >= 0.0f ? 1 : 4, inv.z >= 0.0f ? 2 : 5);
    int sp = walk->sp;
    uint visited = walk->visited;
    int found = 0;
    while (sp > 0) {
        int c = walk->stack[--sp];
        if (c < 0) {
            found = c;
            break;
        }
        __global const BvhNode8 *n = &nodes[c];
        visited++;
        int8 child = n->child;
        int8 hit = box8_meets_segment(n, finite, near, o, inv, tmin, tmax) & (child != 0);
        if (!any(hit)) continue;
        int ch[OCLGI_LANES], h[OCLGI_LANES];
        vstore8(child, 0, ch);
        vstore8(hit, 0, h);
        /* Branch-free compaction: every lane is written, the stack grows by
         * the lanes hit (h = -1); the host sizes the stack for 8 writes. */
        for (int k = 0; k < OCLGI_LANES; ++k) {
            walk->stack[sp] = ch[k];
            sp -= h[k];
        }
    }
    walk->sp = sp;
    walk->visited = visited;
    return found;
}

#endif
