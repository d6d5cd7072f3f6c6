/* photon_trace.cl: light paths from the emitters, every segment stored.
 *
 * photon_trace  one work-item per path. Path p (global id path_offset + i)
 *               writes its segments to slots i * max_depth + b of this
 *               batch (path-major, DESIGN.md section 2), zero-fills the
 *               slots past its end and records its length. Randomness comes
 *               from rng.h keyed by (seed, p, bounce, block), so a batch of
 *               paths is the same whatever the batch size or device.
 *
 * Emission: emitter chosen from a CDF proportional to power; area lights
 * emit from a uniform point of the triangle with a cosine-distributed
 * direction about its normal (one-sided); point lights emit uniformly over
 * the sphere. Each photon carries emitter.power / n_total.
 * Scattering: Lambertian (cosine about the normal on the incoming side),
 * Russian roulette with survival = max albedo, so power never grows.
 */
#include "bvh.h"
#include "rng.h"

inline int emitter_pick(__global const float *cdf, int n, float u)
{
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (u < cdf[mid]) hi = mid; else lo = mid + 1;
    }
    return lo;
}

__kernel void photon_trace(SCENE_ARGS,
                           __global const float4 *tri_normals, __global const int *tri_material,
                           __global const Material *materials,
                           __global const Emitter *emitters, __global const float *emitter_cdf,
                           int n_emitters, uint seed_lo, uint seed_hi,
                           int path_offset, int n_paths, float inv_n_total,
                           int max_depth, float eps,
                           __global Segment *segments, __global int *path_len)
{
    int i = get_global_id(0);
    if (i >= n_paths) return;
    uint path = (uint)(path_offset + i);

    float4 r0 = rng_uniform4(seed_lo, seed_hi, path, 0, 0);
    float4 r1 = rng_uniform4(seed_lo, seed_hi, path, 0, 1);
    __global const Emitter *em = &emitters[emitter_pick(emitter_cdf, n_emitters, r0.x)];
    float3 o, d;
    if (em->kind == EMITTER_TRIANGLE) {
        float3 e1 = vload3(0, em->e1), e2 = vload3(0, em->e2);
        float3 n = normalize(cross(e1, e2));
        float su = sqrt(r0.y);
        o = vload3(0, em->p) + su * (1.0f - r0.z) * e1 + su * r0.z * e2 + eps * n;
        d = sample_cosine(n, r0.w, r1.x);
    } else {
        o = vload3(0, em->p);
        d = sample_sphere(r0.y, r0.z);
    }
    float3 power = vload3(0, em->power) * inv_n_total;

    __global Segment *out = &segments[(size_t)i * max_depth];
    int len = 0;
    for (int b = 0; b < max_depth; ++b) {
        Hit h;
        scene_closest_hit(SCENE_PASS, o, d, INFINITY, &h);
        vstore3(o, 0, out[b].org);
        out[b].t_end = h.tri >= 0 ? h.t : INFINITY;
        vstore3(d, 0, out[b].dir);
        out[b].tri = h.tri;
        vstore3(power, 0, out[b].power);
        out[b].path = (int)path;
        len = b + 1;
        if (h.tri < 0 || b + 1 == max_depth) break;

        __global const Material *m = &materials[tri_material[h.tri]];
        float4 r = rng_uniform4(seed_lo, seed_hi, path, (uint)(b + 1), 0);
        if (!(r.z < m->survive)) break;
        power *= vload3(0, m->albedo) / m->survive;
        float3 n = tri_normals[h.tri].xyz;
        if (dot(n, d) > 0.0f) n = -n;
        o = o + h.t * d + eps * n;
        d = sample_cosine(n, r.x, r.y);
    }
    for (int b = len; b < max_depth; ++b) {
        vstore3((float3)(0.0f), 0, out[b].org);
        out[b].t_end = 0.0f;
        vstore3((float3)(0.0f), 0, out[b].dir);
        out[b].tri = -1;
        vstore3((float3)(0.0f), 0, out[b].power);
        out[b].path = (int)path;
    }
    path_len[i] = len;
}
