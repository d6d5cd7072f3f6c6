/* final_gather.cl: DETP's final gathering (oclgi/estimators/final_gather.py).
 *
 * final_gather_rays     one work-item per ray g = i * n_rays + j (point i,
 *     ray j): a cosine-distributed direction on the point's side of its
 *     normal, traced from the point lifted eps along the normal. Through
 *     mirrors, glass and highlights it goes on as a camera ray does
 *     (camera.cl, the same rules) until it meets a surface with a diffuse
 *     part: that surface's point (w = the triangle's id, as_float), its
 *     geometric normal turned towards the arriving ray, and the weight its
 *     irradiance is seen with: the product of the sample weights on the way
 *     times the diffuse albedo there (texture and vertex colours included),
 *     over p_d for a modified Phong surface. So the radiance arriving at x
 *     along the ray is weight * E(h) / pi, and with cosine sampling
 *     (pdf cos / pi) E_ind(x) = (1 / N) sum_j weight_j E(h_j). A ray that
 *     leaves the scene, is absorbed, meets the black back of a one-sided
 *     surface or is still going after OCLGI_CAMERA_MAX_DEPTH surfaces
 *     gives weight 0 and a zero normal (no disc: nothing can cross it).
 *     Emitted light: what x sees of an emitter straight on is its direct
 *     light (detp_direct.cl samples it), so a ray's first surface adds no
 *     emission; past a mirror, glass or a highlight no light sample can
 *     reach, so the front of an emitting triangle met there (tri_emitter)
 *     or the sky the ray leaves to adds pi * weight * L_e to ``emitted``
 *     (the radiance arriving at x is weight * L_e; cosine sampling's pdf
 *     cos / pi). The sun's light through a mirror (a delta seen through a
 *     delta) reaches x by no ray: it is lost, as a caustic in a gather is.
 *
 * Directions are stratified: the first s^2 rays of a point (s = floor(
 *     sqrt(n_rays))) take one cell each of an s x s grid over the unit
 *     square of (u1, u2), jittered in the cell; the rest are plain random.
 *     Random numbers: rng.h keyed by the run's seed (seed_lo, seed_hi) xor
 *     the gather's own constants, the point i as the path, j *
 *     OCLGI_CAMERA_MAX_DEPTH + surface as the bounce and 2 gather_seed (+1
 *     for the direction's jitter) as the block: a pure function of (seeds,
 *     point, ray, surface), so the rays are the same whatever the launch,
 *     the batch or the work-group size.
 *
 * final_gather_resolve  one work-item per point: out_i += (1 / N) sum_j
 *     (weight_ij E(h_ij) + emitted_ij), j in order 0 .. N-1 (E the hits' resolved DETP
 *     irradiance, itself from 64-bit fixed-point sums). One work-item owns a
 *     point and adds its rays in a fixed order, so the result does not
 *     depend on the work-group size or the order the rays were traced in.
 */
#include "background.h"
#include "bsdf.h"
#include "bvh.h"
#include "rng.h"
#include "texture.h"

#define GATHER_SEED_LO 0x27D4EB2Fu
#define GATHER_SEED_HI 0x165667B1u

__kernel void final_gather_rays(SCENE_ARGS, TEXTURE_ARGS, __global const float4 *tri_normals,
                                __global const int *tri_material, __global const Material *materials,
                                __global const int *tri_emitter, __global const float4 *spread_info,
                                __global const Background *bg, __global const float4 *bg_texels,
                                __global const float4 *points, __global const float4 *point_normals,
                                int n_points, int n_rays, uint seed_lo, uint seed_hi, uint gather_seed, float eps,
                                __global float4 *positions, __global float4 *normals,
                                __global float2 *barys, __global float4 *weights, __global float4 *emitted)
{
    int g = get_global_id(0);
    if (g >= n_points * n_rays) return;
    int i = g / n_rays, j = g % n_rays;
    float3 nx = point_normals[i].xyz;
    float len = length(nx);
    /* a point with no normal (a camera pixel that saw nothing) gathers nothing */
    positions[g] = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
    normals[g] = (float4)(0.0f);
    barys[g] = (float2)(0.0f);
    weights[g] = (float4)(0.0f);
    emitted[g] = (float4)(0.0f);
    if (!(len > 0.0f)) return;
    nx /= len;
    uint s_lo = GATHER_SEED_LO ^ seed_lo, s_hi = GATHER_SEED_HI ^ seed_hi;
    float4 u = rng_uniform4(s_lo, s_hi, (uint)i, (uint)(j * OCLGI_CAMERA_MAX_DEPTH), 2u * gather_seed + 1u);
    int s = (int)sqrt((float)n_rays);
    while ((s + 1) * (s + 1) <= n_rays) ++s;
    while (s * s > n_rays) --s;
    float u1 = u.x, u2 = u.y;
    if (j < s * s) { /* stratified: cell (j % s, j / s), jittered */
        u1 = ((float)(j % s) + u.x) / (float)s;
        u2 = ((float)(j / s) + u.y) / (float)s;
    }
    float3 d = sample_cosine(nx, fmin(u1, 0x1.fffffep-1f), u2);
    float3 o = points[i].xyz + eps * nx;
    float3 weight = (float3)(1.0f);
    for (int depth = 0; depth < OCLGI_CAMERA_MAX_DEPTH; ++depth) {
        Hit h;
        scene_closest_hit(SCENE_PASS, o, d, INFINITY, &h);
        if (h.tri < 0) { /* left the scene: the sky, past a mirror or glass */
            if (depth > 0) emitted[g] = (float4)(OCLGI_PI * weight * background_radiance(bg, bg_texels, d), 0.0f);
            return;
        }
        float3 p = o + h.t * d;
        __global const Material *m = &materials[tri_material[h.tri]];
        float3 n = tri_normals[h.tri].xyz;
        int front = dot(n, d) < 0.0f;
        int k = tri_emitter[h.tri];
        if (depth > 0 && front && k >= 0) emitted[g] = (float4)(OCLGI_PI * weight * spread_info[k].xyz, 0.0f);
        float3 ns = front ? n : -n;
        float4 r = rng_uniform4(s_lo, s_hi, (uint)i, (uint)(j * OCLGI_CAMERA_MAX_DEPTH + depth), 2u * gather_seed);
        int kind = m->kind;
        if (kind == OCLGI_BSDF_DIFFUSE || kind == OCLGI_BSDF_PHONG) {
            if (!front && !(m->flags & OCLGI_MATERIAL_TWOSIDED)) return; /* a black back */
            float pd = kind == OCLGI_BSDF_PHONG ? phong_p_diffuse(m) : 1.0f;
            if (r.w < pd) {
                float3 rho = texture_albedo(TEXTURE_PASS, instances, m, h.tri, p);
                positions[g] = (float4)(p, as_float(h.tri));
                normals[g] = (float4)(normalize(ns), 0.0f);
                barys[g] = (float2)(h.u, h.v);
                weights[g] = (float4)(weight * rho / pd, 0.0f);
                return;
            }
            float3 wi;
            weight *= phong_lobe_sample(m, ns, -d, r, &wi) / (1.0f - pd);
            d = wi;
        } else {
            BsdfSample bs = bsdf_sample(m, n, -d, r, 0);
            weight *= bs.weight;
            d = bs.wi;
        }
        if (!(fmax(weight.x, fmax(weight.y, weight.z)) > 0.0f)) return;
        o = p + eps * (dot(d, ns) < 0.0f ? -ns : ns);
    }
}

__kernel void final_gather_resolve(__global const float4 *hit_irradiance, __global const float4 *weights,
                                   __global const float4 *emitted, int n_points, int n_rays, __global float4 *out)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    float3 sum = (float3)(0.0f);
    size_t base = (size_t)i * (size_t)n_rays;
    for (int j = 0; j < n_rays; ++j)
        sum += weights[base + j].xyz * hit_irradiance[base + j].xyz + emitted[base + j].xyz;
    out[i] += (float4)(sum * (1.0f / (float)n_rays), 0.0f);
}
