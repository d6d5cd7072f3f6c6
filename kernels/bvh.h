/* bvh.h: closest-hit and any-hit traversal of a flattened BVH.
 *
 * Node layout (oclgi_types.h): inner nodes keep their two children adjacent
 * (first, first + 1), leaves a run of triangles in BVH order. The host
 * guarantees the depth fits OCLGI_BVH_STACK_SIZE. Traversal visits the
 * nearer child first and keeps each pushed node's entry distance, so a node
 * farther than the best hit is dropped when popped.
 *
 * Two levels: a scene of instances will call these per instance with the
 * ray moved into the instance's frame; nothing here assumes one mesh.
 */
#ifndef OCLGI_BVH_H
#define OCLGI_BVH_H

#include "oclgi_types.h"
#include "geometry.h"

typedef struct {
    float t, u, v;
    int tri; /* scene-order triangle id, -1 for a miss */
} Hit;

/* Entry distance of the ray into a node's box, INFINITY when it misses the
 * box before tmax. fmin/fmax drop the NaN of 0 * inf (ray on a slab plane). */
inline float bvh_box_entry(__global const BvhNode *n, float3 o, float3 inv, float tmax)
{
    float3 t0 = (vload3(0, n->lo) - o) * inv;
    float3 t1 = (vload3(0, n->hi) - o) * inv;
    float3 tn = fmin(t0, t1), tf = fmax(t0, t1);
    float enter = fmax(fmax(tn.x, tn.y), fmax(tn.z, 0.0f));
    /* 1 + 2 ulp-ish slack keeps rays grazing a face of the box. */
    float leave = fmin(fmin(tf.x, tf.y), fmin(tf.z, tmax)) * 1.0000004f;
    return enter <= leave ? enter : INFINITY;
}

inline int bvh_traverse(__global const BvhNode *nodes, __global const Tri *tris,
                        float3 o, float3 d, float tmax, int any_hit, Hit *hit)
{
    float3 inv = 1.0f / d;
    RayShear shear = ray_shear(d);
    int stack[OCLGI_BVH_STACK_SIZE];
    float stack_t[OCLGI_BVH_STACK_SIZE];
    int sp = 0;
    hit->tri = -1;
    hit->t = tmax;
    if (bvh_box_entry(&nodes[0], o, inv, tmax) == INFINITY) return -1;
    int node = 0;
    for (;;) {
        __global const BvhNode *n = &nodes[node];
        if (n->count > 0) {
            int end = n->first + n->count;
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
            float t0 = bvh_box_entry(&nodes[c], o, inv, hit->t);
            float t1 = bvh_box_entry(&nodes[c + 1], o, inv, hit->t);
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

inline int bvh_closest_hit(__global const BvhNode *nodes, __global const Tri *tris,
                           float3 o, float3 d, float tmax, Hit *hit)
{
    return bvh_traverse(nodes, tris, o, d, tmax, 0, hit);
}

inline int bvh_any_hit(__global const BvhNode *nodes, __global const Tri *tris,
                       float3 o, float3 d, float tmax)
{
    Hit hit;
    return bvh_traverse(nodes, tris, o, d, tmax, 1, &hit) >= 0;
}

#endif
