/* bvh.h: closest-hit and any-hit traversal of the scene's two-level BVH.
 *
 * Bottom level: one BVH per object (oclgi_types.h BvhNode; children of an
 * inner node adjacent at first and first + 1, leaves a run of triangles in
 * BVH order; all objects' nodes in one array, each object's root given by
 * its Instance). Top level: the instances, each a world-space box and a
 * transform; a ray is moved into an object's frame (the direction is not
 * renormalised, so distances t stay world distances) and traversed there.
 * Moving an object changes its Instance only: no BVH is rebuilt. The top
 * level is a flat list: a move touches one record, and scenes have few
 * movable objects (a BVH over instances when they have many).
 *
 * Traversal visits the nearer child first and keeps each pushed node's entry
 * distance, so a node farther than the best hit is dropped when popped. The
 * host guarantees every depth fits OCLGI_BVH_STACK_SIZE.
 *
 * Kernels take the scene as SCENE_ARGS and pass it on as SCENE_PASS.
 */
#ifndef OCLGI_BVH_H
#define OCLGI_BVH_H

#include "oclgi_types.h"
#include "geometry.h"
#include "box.h"

#define SCENE_ARGS __global const BvhNode *nodes, __global const Tri *tris, \
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

/* One object's BVH from its root; hit->t is the current limit and is
 * lowered by every hit found. */
inline int bvh_traverse(__global const BvhNode *nodes, __global const Tri *tris, int root,
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

inline int scene_traverse(SCENE_ARGS, float3 o, float3 d, float tmax, int any_hit, Hit *hit)
{
    hit->tri = -1;
    hit->t = tmax;
    float3 inv = 1.0f / d;
    for (int k = 0; k < n_instances; ++k) {
        __global const Instance *in = &instances[k];
        if (box_entry(in->lo, in->hi, o, inv, hit->t) == INFINITY) continue;
        float3 lo = xform_point(in->object_from_world, o);
        float3 ld = xform_vector(in->object_from_world, d);
        if (bvh_traverse(nodes, tris, in->root, lo, ld, any_hit, hit) >= 0 && any_hit) break;
    }
    return hit->tri;
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
