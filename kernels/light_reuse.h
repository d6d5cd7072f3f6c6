/* light_reuse.h: what light_reuse.cl's kernels and light_reweight.cl share:
 * a stored path's first hit, a light position's density there, and the
 * factors frame j gives a stored path (one function, so that a frame and
 * its re-weighting compute them from the same floats in the same order).
 */
#ifndef OCLGI_LIGHT_REUSE_H
#define OCLGI_LIGHT_REUSE_H

#include "bvh.h"
#include "light.h"
#include "segment.h"

/* pbrt-v4's spot profile, as light_sample_le applies it; 1 for a point. */
inline float reuse_profile(__global const Emitter *em, float3 d)
{
    if (em->kind != OCLGI_EMITTER_SPOT) return 1.0f;
    return light_smoothstep(dot(d, vload3(0, em->e1)), em->a, em->b);
}

/* The density (per m^2 at x, visibility left out) of light em emitting a
 * photon whose first hit is x on a surface of normal n, arriving on the
 * side `side` (the sign of dot(n, d) of the stored segment 0): light_pdf_dir
 * times cos / r^2. 0 when the light is on the other side or does not emit
 * towards x. *d and *r: the direction and distance from the light to x. */
inline float reuse_density(__global const Emitter *em, __global const float *table, float3 x, float3 n,
                           float side, float3 *d, float *r)
{
    float3 v = x - vload3(0, em->p);
    float r2 = dot(v, v);
    *r = sqrt(r2);
    *d = v / *r;
    if (!(r2 > 0.0f)) return 0.0f;
    float c = dot(n, *d);
    if (!(c * side > 0.0f)) return 0.0f;
    return light_pdf_dir(em, *d, table) * fabs(c) / r2;
}

/* Can light position em see x? Nothing is hit on the way there short of
 * x less eps (the ray offset of oclgi/scene/compiled.py): x's own
 * triangle, or a neighbour of the same face at an edge, lies beyond. An
 * any-hit query: the first occluder found ends it. */
inline int reuse_visible(SCENE_ARGS, __global const Emitter *em, float3 d, float r, float eps)
{
    return !scene_any_hit(SCENE_PASS, vload3(0, em->p), d, r - eps);
}

/* The first hit of a stored path: 0 when segment 0 escaped. */
inline int reuse_first_hit(__global const Segment *slot, __global const float4 *tri_normals, float3 *x,
                           float3 *n, float *side, int *tri)
{
    SegmentView s;
    if (!segment_read(slot, &s) || s.tri < 0) return 0;
    *x = segment_end(&s);
    *n = tri_normals[s.tri].xyz;
    *side = dot(*n, s.w) > 0.0f ? 1.0f : -1.0f;
    *tri = s.tri;
    return 1;
}

/* Frame `frame`'s factors for stored path i (its slots at src): 0 when the
 * path gives the frame nothing (segment 0 escaped, or the frame's position
 * cannot see its first hit: bit `seen`); else segment 0 from the light (d,
 * r towards the first hit on triangle tri) carries the light's record
 * power times *c, and the tail's stored powers times *scale. */
inline int reuse_path_frame(__global const float4 *tri_normals, __global const Emitter *lights,
                            __global const float *table, int frame, int paths_per_position,
                            __global const Segment *src, float density_sum, uint seen,
                            float3 *d, float *r, int *tri, float *c, float *scale)
{
    float3 x, n;
    float side;
    if (!seen || !reuse_first_hit(src, tri_normals, &x, &n, &side, tri)) return 0;
    __global const Emitter *em = &lights[frame];
    float p = reuse_density(em, table, x, n, side, d, r);
    *c = reuse_profile(em, *d) * (p / density_sum);
    /* the profile the stored path was traced with, from its own direction */
    SegmentView s0;
    segment_load(src, &s0);
    float traced = reuse_profile(&lights[src->path / paths_per_position], s0.w);
    *scale = traced > 0.0f ? *c / traced : 0.0f;
    return 1;
}

/* Bit `frame` of stored path i's visibility words. */
inline uint reuse_seen(__global const uint *visible, int words_per_path, int i, int frame)
{
    return (visible[(size_t)i * words_per_path + (frame >> 5)] >> (frame & 31)) & 1u;
}

#endif
