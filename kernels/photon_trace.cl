/* photon_trace.cl: light paths from the emitters, every segment stored.
 *
 * photon_trace    one work-item per path. Path p (global id path_offset + i)
 *                 writes its segments to slots i * max_depth + b of the
 *                 store (path-major, DESIGN.md section 2; segment.h),
 *                 zero-fills the slots past its end and records its length.
 * photon_retrace  one work-item per listed path: re-traces path p from its
 *                 bounce b on (the suffix), overwriting its own slots b.. and
 *                 nothing else. Used after a move: the segments before b are
 *                 unchanged, and the suffix is the one a full trace of the
 *                 moved scene gives, bit for bit: both kernels run the same
 *                 path_scatter / path_trace_from code on the same stored
 *                 float values with the same random numbers.
 *
 * Randomness comes from rng.h keyed by (seed, path, bounce, block), so a
 * path is the same whatever the batch, the device or the kernel tracing it.
 * Emission: emitter chosen from a CDF proportional to power, then sampled
 * by its kind in light.h (area, point, spot, sun, sky, environment map;
 * emitter_cdf holds the maps' tables after its n_emitters CDF values).
 * Each photon carries at most emitter.power, in units of the largest power
 * any emitter gives a photon (oclgi_types.h): the same for a path whatever
 * the run's photon count, which only its resolve divides by.
 * Scattering: by the surface's material (bsdf.h), with Russian roulette on
 * the sample's weight, so power never grows.
 */
#include "bsdf.h"
#include "bvh.h"
#include "light.h"
#include "prefetch.h"
#include "rng.h"
#include "segment.h"
#include "texture.h"

#define TRACE_ARGS __global const float4 *tri_normals, __global const int *tri_material,     \
                   __global const Material *materials, TEXTURE_ARGS,                        \
                   __global const Emitter *emitters,                                        \
                   __global const float *emitter_cdf, int n_emitters, uint seed_lo,        \
                   uint seed_hi, int max_depth, float eps
#define TRACE_PASS tri_normals, tri_material, materials, TEXTURE_PASS, emitters, emitter_cdf, n_emitters, \
                   seed_lo, seed_hi, max_depth, eps

typedef struct {
    float3 o, d, power; /* the next segment's origin, direction and power */
} PathState;

/* Event 0: the photon leaves a light (light.h, with this event's blocks 0
 * and 1: r0.x chooses the emitter, the kind uses the rest). */
inline PathState path_emit(TRACE_ARGS, uint path)
{
    float4 r0 = rng_uniform4(seed_lo, seed_hi, path, 0, 0);
    float4 r1 = rng_uniform4(seed_lo, seed_hi, path, 0, 1);
    __global const Emitter *em = &emitters[light_pick(emitter_cdf, n_emitters, r0.x)];
    LightSample l = light_sample_le(em, r0, r1, eps, emitter_cdf);
    PathState s;
    s.o = l.o;
    s.d = l.d;
    s.power = l.power;
    return s;
}

/* Event b >= 1: the photon that ran along segment (o, d, t) to triangle tri
 * with the given power scatters there (bsdf.h), or is absorbed (returns 0).
 * Russian roulette survives with q = min(1, the sample weight's largest
 * component) and divides by it, so power never grows (oclgi_types.h); for
 * a diffuse surface q is the max albedo, as before the kinds existed. The
 * next segment starts eps off the surface on the side it leaves by. */
inline int path_scatter(TRACE_ARGS, __global const Instance *instances, uint path, int b, float3 o, float3 d,
                        float t, int tri, float3 power, PathState *s)
{
    if (tri < 0 || b >= max_depth) return 0;
    __global const Material *m = &materials[tri_material[tri]];
    float4 r = rng_uniform4(seed_lo, seed_hi, path, (uint)b, 0);
    float3 n = tri_normals[tri].xyz;
    BsdfSample bs = bsdf_sample(m, n, -d, r, 1);
    /* only diffuse materials have textures and vertex colours (oclgi/scene/materials.py) */
    if (m->texture >= 0 || (m->flags & OCLGI_MATERIAL_VERTEX_COLOUR))
        bs.weight *= albedo_tint(TEXTURE_PASS, instances, m, tri, o + t * d);
    float q = fmin(1.0f, fmax(bs.weight.x, fmax(bs.weight.y, bs.weight.z)));
    if (!(r.z < q)) return 0;
    s->power = power * bs.weight / q;
    if (dot(n, d) > 0.0f) n = -n; /* the side the photon came from */
    s->o = o + t * d + eps * (bs.flags & BSDF_TRANSMITTED ? -n : n);
    s->d = bs.wi;
    return 1;
}

/* Trace from event b in state s to the path's end: slots b.. of `out`
 * (the path's own slots) are written, the rest zero-filled. Returns the
 * path's length in segments. */
inline int path_trace_from(SCENE_ARGS, TRACE_ARGS, uint path, int b, PathState s, __global Segment *out)
{
    int len = b;
    for (;;) {
        Hit h;
        scene_closest_hit(SCENE_PASS, s.o, s.d, INFINITY, &h);
        float t = h.tri >= 0 ? h.t : INFINITY;
        segment_write(&out[b], s.o, t, s.d, h.tri, s.power, (int)path);
        len = b + 1;
        PathState next;
        if (!path_scatter(TRACE_PASS, instances, path, b + 1, s.o, s.d, h.t, h.tri, s.power, &next)) break;
        s = next;
        ++b;
    }
    for (int k = len; k < max_depth; ++k) segment_write_empty(&out[k], (int)path);
    return len;
}

__kernel void photon_trace(SCENE_ARGS, TRACE_ARGS, int path_offset, int n_paths,
                           __global Segment *segments, __global int *path_len)
{
    int i = get_global_id(0);
    if (i >= n_paths) return;
    uint path = (uint)(path_offset + i);
    PathState s = path_emit(TRACE_PASS, path);
    path_len[i] = path_trace_from(SCENE_PASS, TRACE_PASS, path, 0, s, &segments[(size_t)i * max_depth]);
}

/* paths[k]: index of a path in the store (its global id is path_offset +
 * that index); starts[k]: the first bounce to re-trace. */
__kernel void photon_retrace(SCENE_ARGS, TRACE_ARGS, int path_offset,
                             __global const int *paths, __global const int *starts, int n_list,
                             __global Segment *segments, __global int *path_len)
{
    int k = get_global_id(0);
    if (k >= n_list) return;
    int i = paths[k], b = starts[k];
    prefetch_resumed_path(segments, paths, starts, k, n_list, max_depth);
    uint path = (uint)(path_offset + i);
    __global Segment *out = &segments[(size_t)i * max_depth];
    PathState s;
    if (b == 0) {
        s = path_emit(TRACE_PASS, path);
    } else {
        SegmentView prev;
        segment_load(&out[b - 1], &prev);
        if (!path_scatter(TRACE_PASS, instances, path, b, prev.o, prev.w, prev.t_end, prev.tri,
                          segment_power(&out[b - 1]), &s)) {
            for (int j = b; j < max_depth; ++j) segment_write_empty(&out[j], (int)path);
            path_len[i] = b;
            return;
        }
    }
    path_len[i] = path_trace_from(SCENE_PASS, TRACE_PASS, path, b, s, out);
}
