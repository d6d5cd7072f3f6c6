/* box_bvh.h: walking a BVH over boxes (segment pieces, impact balls) for
 * overlap queries with a box.
 *
 * The trees come from oclgi/accel/bvh_build.py (BvhNode, oclgi_types.h):
 * inner nodes have their two children adjacent at first and first + 1,
 * leaves a run [first, first + count) of primitives. Unlike bvh.h (closest
 * hit, nearest child first), a DETP query needs EVERY leaf whose box meets
 * the query, in any order, so the walk is a plain depth-first stack.
 *
 * Use as an iterator, so each kernel keeps its own leaf loop:
 *
 *     BoxBvhWalk walk;
 *     box_bvh_start(&walk);
 *     int leaf;
 *     while ((leaf = box_bvh_next_box(&walk, nodes, lo, hi)) >= 0) { ... }
 *     WORK_NODE(walk.visited);
 *
 * `visited` counts nodes whose box was tested (the root included).
 * The host checks that the tree's depth fits OCLGI_BOX_BVH_STACK (a node
 * pushes at most its two children, so depth + 1 entries suffice).
 *
 * Conservative tests: the boxes are padded on the host (see
 * oclgi/estimators/detp_ray_map.py) by far more than float32 rounding can
 * move a crossing point, and the box test below is exact, so no segment
 * that DETP_TEST (detp.h) accepts is culled.
 */
#ifndef OCLGI_BOX_BVH_H
#define OCLGI_BOX_BVH_H

#include "oclgi_types.h"
#include "box.h"

typedef struct {
    int stack[OCLGI_BOX_BVH_STACK];
    int sp;
    uint visited;
} BoxBvhWalk;

inline void box_bvh_start(BoxBvhWalk *walk)
{
    walk->stack[0] = 0; /* the root */
    walk->sp = 1;
    walk->visited = 0;
}

/* Do two closed boxes overlap? Comparisons only: exact. */
inline int box_meets_box(__global const BvhNode *n, float3 lo, float3 hi)
{
    float3 nlo = vload3(0, n->lo), nhi = vload3(0, n->hi);
    return nlo.x <= hi.x && lo.x <= nhi.x && nlo.y <= hi.y && lo.y <= nhi.y && nlo.z <= hi.z &&
           lo.z <= nhi.z;
}

/* The next leaf (node index) whose box overlaps [lo, hi], -1 when done. */
inline int box_bvh_next_box(BoxBvhWalk *walk, __global const BvhNode *nodes, float3 lo, float3 hi)
{
    while (walk->sp > 0) {
        int i = walk->stack[--walk->sp];
        __global const BvhNode *n = &nodes[i];
        walk->visited++;
        if (!box_meets_box(n, lo, hi)) continue;
        if (n->count > 0) return i;
        walk->stack[walk->sp++] = n->first + 1;
        walk->stack[walk->sp++] = n->first;
    }
    return -1;
}

#endif
