/* bvh.h: closest-hit and any-hit traversal of the scene's two-level BVH.
 *
 * Bottom level: one BVH per object, all objects' nodes in one array, each
 * object's root given by its Instance, in one of two layouts (the host's
 * choice, oclgi/scene/compiled.py):
 *   - binary (Instance.root >= 0): oclgi_types.h BvhNode, children of an
 *     inner node adjacent at first and first + 1, leaves a run of triangles
 *     in BVH order;
 *   - wide (Instance.root < 0, the root node is ~root): the same binary
 *     tree collapsed into BvhNode8 nodes of up to 8 children
 *     (oclgi/accel/bvh_wide.py) whose boxes are slabbed all at once, one
 *     float8 op per plane (PoCL does not vectorise across work-items: the
 *     lanes are written out); a leaf is TriBlock4 records after the nodes
 *     in the same buffer (oclgi/accel/bvh_leaf_blocks.py), tested 4
 *     triangles at a time (geometry.h tri4_intersect).
 * Top level: the instances, each a world-space box and a
 * transform; a ray is moved into an object's frame (the direction is not
 * renormalised, so distances t stay world distances) and traversed there.
 * Moving an object changes its Instance only: no BVH is rebuilt. The top
 * level is a flat list, its boxes tested 8 at a time (scene_traverse): a
 * move touches one record and one group of boxes.
 *
 * Both traversals visit the nearer children first and keep each pushed
 * node's entry distance, so a node farther than the best hit is dropped
 * when popped. They compute every box entry with the same slab arithmetic
 * (box.h's) and test leaves' triangles in the same order with the same
 * test, so they return the same hit bit for bit, but for which of two
 * triangles at exactly the same distance is found first. The host
 * guarantees every traversal fits its stack (OCLGI_BVH_STACK_SIZE entries
 * binary, BVH_WIDE_STACK wide).
 *
 * Kernels take the scene as SCENE_ARGS and pass it on as SCENE_PASS.
 */
#ifndef OCLGI_BVH_H
#define OCLGI_BVH_H

#include "oclgi_types.h"
#include "geometry.h"
#include "box.h"

#define SCENE_ARGS __global const void *nodes, __global const Tri *tris, \
                   __global const Instance *instances, int n_instances
#define SCENE_PASS nodes, tris, instances, n_instances

typedef struct {
    float t, u, v;
    int tri; /* scene-order triangle id, -1 for a miss */
#if OCLGI_BVH_COUNT
    int nodes, tests; /* traversal work: nodes visited, triangles tested */
#endif
} Hit;

/* Work counters, compiled in only where a program asks (bvh_query.cl's
 * bvh_query_count, for the BVH benchmarks): every other program's
 * traversal is the same code with or without them. */
#if OCLGI_BVH_COUNT
#define BVH_COUNT(hit, field, k) ((hit)->field += (k))
#else
#define BVH_COUNT(hit, field, k)
#endif

/* Entry distance of the ray into a box (box.h), INFINITY when it misses the
 * box before tmax. */
inline float box_entry3(float3 lo, float3 hi, float3 o, float3 inv, float tmax)
{
    float enter;
    return box_slab(lo, hi, o, inv, tmax, &enter) ? enter : INFINITY;
}

inline float box_entry(__global const float *lo, __global const float *hi, float3 o, float3 inv, float tmax)
{
    return box_entry3(vload3(0, lo), vload3(0, hi), o, inv, tmax);
}

/* Affine 3x4 transforms stored as 12 floats, row-major (a b c t per row). */
inline float3 xform_point(__global const float *m, float3 p)
{
    float4 r0 = vload4(0, m), r1 = vload4(1, m), r2 = vload4(2, m);
    return (float3)(r0.x * p.x + r0.y * p.y + r0.z * p.z + r0.w,
                    r1.x * p.x + r1.y * p.y + r1.z * p.z + r1.w,
                    r2.x * p.x + r2.y * p.y + r2.z * p.z + r2.w);
}

inline float3 xform_vector(__global const float *m, float3 v)
{
    float4 r0 = vload4(0, m), r1 = vload4(1, m), r2 = vload4(2, m);
    return (float3)(r0.x * v.x + r0.y * v.y + r0.z * v.z,
                    r1.x * v.x + r1.y * v.y + r1.z * v.z,
                    r2.x * v.x + r2.y * v.y + r2.z * v.z);
}

/* One object's binary BVH from its root; hit->t is the current limit and
 * is lowered by every hit found. */
inline int bvh2_traverse(__global const BvhNode *nodes, __global const Tri *tris, int root,
                         float3 o, float3 d, int any_hit, Hit *hit)
{
    float3 inv = 1.0f / d;
    RayShear shear = ray_shear(d);
    int stack[OCLGI_BVH_STACK_SIZE];
    float stack_t[OCLGI_BVH_STACK_SIZE];
    int sp = 0;
    if (box_entry(nodes[root].lo, nodes[root].hi, o, inv, hit->t) == INFINITY) return hit->tri;
    int node = root;
    for (;;) {
        __global const BvhNode *n = &nodes[node];
        BVH_COUNT(hit, nodes, 1);
        if (n->count > 0) {
            int end = n->first + n->count;
            BVH_COUNT(hit, tests, n->count);
            for (int i = n->first; i < end; ++i) {
                __global const Tri *tr = &tris[i];
                float t, u, v;
                if (tri_intersect(o, shear, vload3(0, tr->v0), vload3(0, tr->v1), vload3(0, tr->v2),
                                  hit->t, &t, &u, &v)) {
                    hit->t = t; hit->u = u; hit->v = v; hit->tri = tr->id;
                    if (any_hit) return hit->tri;
                }
            }
        } else {
            int c = n->first;
            float t0 = box_entry(nodes[c].lo, nodes[c].hi, o, inv, hit->t);
            float t1 = box_entry(nodes[c + 1].lo, nodes[c + 1].hi, o, inv, hit->t);
            if (t0 != INFINITY || t1 != INFINITY) {
                if (t0 == INFINITY) { node = c + 1; continue; }
                if (t1 == INFINITY) { node = c; continue; }
                int near = t0 <= t1 ? c : c + 1;
                stack[sp] = t0 <= t1 ? c + 1 : c;
                stack_t[sp] = fmax(t0, t1);
                ++sp;
                node = near;
                continue;
            }
        }
        /* pop the next node still nearer than the best hit */
        for (;;) {
            if (sp == 0) return hit->tri;
            --sp;
            if (stack_t[sp] <= hit->t) break;
        }
        node = stack[sp];
    }
}

/* The wide traversal's stack: a node stores a whole vector of entries at
 * the top (oclgi/accel/bvh_wide.py WIDE_STACK mirrors it and checks every
 * tree against it). */
#define BVH_WIDE_STACK (2 * OCLGI_BVH_STACK_SIZE)

/* One step of a sorting network over 8 int lanes: each lane meets lane
 * perm[i] and keeps the min where mask is set, else the max. */
#define BVH_SORT_STEP(k, p0, p1, p2, p3, p4, p5, p6, p7, m0, m1, m2, m3, m4, m5, m6, m7) do { \
        int8 w_ = shuffle(k, (uint8)(p0, p1, p2, p3, p4, p5, p6, p7)); \
        k = select(max(k, w_), min(k, w_), (int8)(m0, m1, m2, m3, m4, m5, m6, m7)); } while (0)

/* max/min of lanes without NaN: the compare-and-select one instruction does. */
#define BVH_MAX8(a, b) select((b), (a), (a) > (b))
#define BVH_MIN8(a, b) select((b), (a), (a) < (b))

/* The 8 keys in descending order (bitonic network, 6 steps). */
HOT_INLINE int8 bvh_sort8_desc(int8 k)
{
    BVH_SORT_STEP(k, 1, 0, 3, 2, 5, 4, 7, 6, 0, -1, -1, 0, 0, -1, -1, 0);
    BVH_SORT_STEP(k, 2, 3, 0, 1, 6, 7, 4, 5, 0, 0, -1, -1, -1, -1, 0, 0);
    BVH_SORT_STEP(k, 1, 0, 3, 2, 5, 4, 7, 6, 0, -1, 0, -1, -1, 0, -1, 0);
    BVH_SORT_STEP(k, 4, 5, 6, 7, 0, 1, 2, 3, 0, 0, 0, 0, -1, -1, -1, -1);
    BVH_SORT_STEP(k, 2, 3, 0, 1, 6, 7, 4, 5, 0, 0, -1, -1, 0, 0, -1, -1);
    BVH_SORT_STEP(k, 1, 0, 3, 2, 5, 4, 7, 6, 0, -1, 0, -1, 0, -1, 0, -1);
    return k;
}

/* The entry and exit distances of a ray into 8 child boxes given by their
 * planes, box_slab's arithmetic lane by lane. `finite`: every 1/d is
 * finite, and the planes come as near (nx, ny, nz) and far (fx, fy, fz)
 * for the ray's signs; then no slab product is NaN and (lo - o) * inv and
 * (hi - o) * inv are ordered by the sign of inv alone (rounding is
 * monotone), so plain max/min (one instruction each) give fmax/fmin's
 * values. Otherwise the planes come as lo and hi (in the same arguments)
 * and box_slab's own NaN-dropping form is used. */
HOT_INLINE void bvh8_slab(int finite, float8 nx, float8 ny, float8 nz, float8 fx, float8 fy, float8 fz,
                         float3 o, float3 inv, float tmax, float8 *enter, float8 *leave)
{
    float8 t0x = (nx - o.x) * inv.x, t1x = (fx - o.x) * inv.x;
    float8 t0y = (ny - o.y) * inv.y, t1y = (fy - o.y) * inv.y;
    float8 t0z = (nz - o.z) * inv.z, t1z = (fz - o.z) * inv.z;
    if (finite) {
        *enter = BVH_MAX8(BVH_MAX8(t0x, t0y), BVH_MAX8(t0z, (float8)(0.0f)));
        *leave = BVH_MIN8(BVH_MIN8(t1x, t1y), BVH_MIN8(t1z, (float8)(tmax))) * 1.0000004f;
    } else {
        *enter = fmax(fmax(fmin(t0x, t1x), fmin(t0y, t1y)), fmax(fmin(t0z, t1z), 0.0f));
        *leave = fmin(fmin(fmax(t0x, t1x), fmax(t0y, t1y)), fmin(fmax(t0z, t1z), tmax)) * 1.0000004f;
    }
}

/* One object's wide BVH from its root node. A node's 8 child boxes are
 * slabbed together (bvh8_slab, box_slab's arithmetic on the same planes as
 * the binary walk, so the same bits). Each hit lane's key is its
 * entry distance with the lane number in the 3 low mantissa bits (entry
 * distances are >= 0, so the int order is the float order; misses are -1);
 * sorted in descending order, the keys' children and distances go to the
 * stack as whole vectors, the farthest deepest, and the nearest is taken
 * straight back off the top. A pushed entry keeps its distance with the
 * lane bits cleared: at most 7 ulps below the true entry, so culling on pop
 * never drops a node the exact distance would keep.
 *
 * A leaf lane holds ~(offset / 32 << 3 | count - 1): its count triangles
 * are in ceil(count / 4) TriBlock4 records from that byte offset in the
 * nodes' buffer, tested in the leaf's order, the lowest lane of equal
 * distances kept (the one a test one by one would keep).
 *
 * An unused lane has the box lo = hi = +inf: along an axis with 1/d >= 0
 * its entry is +inf, and with all three negative its exit is -inf; either
 * way it is a miss (the test below counts an entry of +inf as one, as the
 * binary walk's box_entry does). */
HOT_INLINE int bvh8_traverse(__global const void *nodes, int root, float3 o, float3 d, int any_hit, Hit *hit)
{
    float3 inv = 1.0f / d;
    RayShear shear = ray_shear(d);
    int stack[BVH_WIDE_STACK];
    float stack_t[BVH_WIDE_STACK];
    int sp = 0;
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    /* the near planes' field indices (lo x..z = 0..2, hi x..z = 3..5),
     * chosen once per ray; an axis with d = 0 (1/d infinite)
     * takes the general form */
    int finite = isfinite(inv.x) && isfinite(inv.y) && isfinite(inv.z);
    int3 near = (int3)(inv.x >= 0.0f ? 0 : 3, inv.y >= 0.0f ? 1 : 4, inv.z >= 0.0f ? 2 : 5);
    if (!finite) near = (int3)(0, 1, 2);
    int ref = root;
    for (;;) {
        if (ref >= 0) {
            float8 enter, leave;
            __global const BvhNode8 *n = (__global const BvhNode8 *)nodes + ref;
            __global const float8 *f = &n->lox;
            BVH_COUNT(hit, nodes, 1);
            bvh8_slab(finite, f[near.x], f[near.y], f[near.z], f[3 - near.x], f[5 - near.y], f[7 - near.z],
                      o, inv, hit->t, &enter, &leave);
            int8 child = n->child;
            int8 in = (enter <= leave) & (enter < INFINITY);
            /* -0.0f and +0.0f both become key 0 | lane */
            int8 key = select((int8)(-1), (as_int8(enter) & 0x7FFFFFF8) | lane, in);
            int4 c4 = in.lo + in.hi;
            int2 c2 = c4.lo + c4.hi;
            int n_in = -(c2.x + c2.y);
            if (n_in == 1) { /* the one lane hit has the largest key */
                int4 m4 = max(key.lo, key.hi);
                int2 m2 = max(m4.lo, m4.hi);
                ref = shuffle(child, (uint8)(max(m2.x, m2.y) & 7)).s0;
                continue;
            }
            if (n_in > 1) {
                key = bvh_sort8_desc(key);
                vstore8(shuffle(child, as_uint8(key) & 7u), 0, stack + sp);
                vstore8(as_float8(key & ~7), 0, stack_t + sp);
                sp += n_in - 1;
                ref = stack[sp];
                continue;
            }
        } else {
            int run = ~ref, count = (run & 7) + 1;
            BVH_COUNT(hit, tests, count);
            __global const TriBlock4 *b = (__global const TriBlock4 *)((__global const char *)nodes +
                                                                        ((size_t)(run >> 3) << 5));
            for (int k = 0; k < count; k += 4, ++b) {
                float t, u, v;
                int lane = tri4_intersect(o, shear, &b->v0x, count - k, hit->t, &t, &u, &v);
                if (lane >= 0) {
                    int4 id = b->id;
                    hit->t = t; hit->u = u; hit->v = v;
                    hit->tri = lane == 0 ? id.x : (lane == 1 ? id.y : (lane == 2 ? id.z : id.w));
                    if (any_hit) return hit->tri;
                }
            }
        }
        /* pop the next node still nearer than the best hit */
        for (;;) {
            if (sp == 0) return hit->tri;
            --sp;
            if (stack_t[sp] <= hit->t) break;
        }
        ref = stack[sp];
    }
}

/* One object's BVH, in the layout its Instance's root says (see the top). */
inline int bvh_traverse(__global const void *nodes, __global const Tri *tris, int root,
                        float3 o, float3 d, int any_hit, Hit *hit)
{
    if (root < 0) return bvh8_traverse(nodes, ~root, o, d, any_hit, hit);
    return bvh2_traverse((__global const BvhNode *)nodes, tris, root, o, d, any_hit, hit);
}

/* Up to this many instances are tested one box at a time (box_entry): the
 * group test below cost 1-4% more on one-object scenes (bunny, Sponza). A
 * program may set it (tests/test_instances.py builds one that never groups,
 * to compare the two bit for bit). */
#ifdef OCLGI_SCENE_FLAT_INSTANCES
#define SCENE_FLAT_INSTANCES OCLGI_SCENE_FLAT_INSTANCES
#else
#define SCENE_FLAT_INSTANCES 4
#endif

/* The ray in instance k's object frame, traversed there; 1 when an any-hit
 * query is answered. */
inline int scene_visit(SCENE_ARGS, int k, float3 o, float3 d, int any_hit, Hit *hit)
{
    __global const Instance *in = &instances[k];
    float3 lo = xform_point(in->object_from_world, o);
    float3 ld = xform_vector(in->object_from_world, d);
    return bvh_traverse(nodes, tris, in->root, lo, ld, any_hit, hit) >= 0 && any_hit;
}

/* The top level: every instance whose world box the ray meets before the
 * best hit so far, in index order, traversed in its object's frame. Past
 * SCENE_FLAT_INSTANCES, the boxes come 8 at a time (InstanceBoxes, after
 * the records, from the next 32-byte boundary): bvh8_slab's general form,
 * box_slab's operations lane by lane, gives each lane's entry e and exit
 * (without tmax) times the slack, and each instance is visited, in index
 * order, when e <= min(exit, t * slack) and e is finite, t the best hit
 * then. That is box_entry's own test: rounding is monotone, so min(a, b)
 * times the slack is min(a times it, b times it), and min is exact in any
 * order. So an instance is visited exactly when the one-by-one loop would
 * visit it, and the hits are that loop's, bit for bit.
 *
 * The walk starts from the best hit `hit` already holds (none, for
 * scene_traverse below), so a ray through instances A then B in one buffer
 * finds what a ray through A alone, then through B from A's hit, finds:
 * each instance's test and walk read the best hit so far, nothing else (a
 * camera session's view: the static layer's hits, then the movable
 * objects', kernels/camera.cl first_in). */
inline int scene_traverse_from(SCENE_ARGS, float3 o, float3 d, int any_hit, Hit *hit)
{
    float3 inv = 1.0f / d;
    if (n_instances <= SCENE_FLAT_INSTANCES) { /* a few: one box at a time costs less than a group */
        for (int k = 0; k < n_instances; ++k) {
            __global const Instance *in = &instances[k];
            if (box_entry(in->lo, in->hi, o, inv, hit->t) == INFINITY) continue;
            if (scene_visit(SCENE_PASS, k, o, d, any_hit, hit)) break;
        }
        return hit->tri;
    }
    size_t at = ((size_t)n_instances * sizeof(Instance) + 31) & ~(size_t)31; /* instance_boxes.py groups_offset */
    __global const InstanceBoxes *groups = (__global const InstanceBoxes *)((__global const char *)instances + at);
    for (int g = 0; g * OCLGI_LANES < n_instances; ++g) {
        __global const InstanceBoxes *b = groups + g;
        float8 enter, leave;
        bvh8_slab(0, b->lox, b->loy, b->loz, b->hix, b->hiy, b->hiz, o, inv, INFINITY, &enter, &leave);
        int8 met = (enter <= fmin(leave, (float8)(hit->t * 1.0000004f))) & (enter != (float8)(INFINITY));
        if (!any(met)) continue;
        float es[OCLGI_LANES], ls[OCLGI_LANES];
        int ms[OCLGI_LANES];
        vstore8(enter, 0, es);
        vstore8(leave, 0, ls);
        vstore8(met, 0, ms);
        int n = min(OCLGI_LANES, n_instances - g * OCLGI_LANES);
        for (int j = 0; j < n; ++j) {
            /* box_entry against the best hit now (it only shrinks) */
            if (!ms[j] || !(es[j] <= fmin(ls[j], hit->t * 1.0000004f))) continue;
            if (scene_visit(SCENE_PASS, g * OCLGI_LANES + j, o, d, any_hit, hit)) return hit->tri;
        }
    }
    return hit->tri;
}

/* The top level from no hit, up to tmax. */
inline int scene_traverse(SCENE_ARGS, float3 o, float3 d, float tmax, int any_hit, Hit *hit)
{
    hit->tri = -1;
    hit->t = tmax;
    return scene_traverse_from(SCENE_PASS, o, d, any_hit, hit);
}

inline int scene_closest_hit(SCENE_ARGS, float3 o, float3 d, float tmax, Hit *hit)
{
    return scene_traverse(SCENE_PASS, o, d, tmax, 0, hit);
}

inline int scene_any_hit(SCENE_ARGS, float3 o, float3 d, float tmax)
{
    Hit hit;
    return scene_traverse(SCENE_PASS, o, d, tmax, 1, &hit) >= 0;
}

#endif
