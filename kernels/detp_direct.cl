/* detp_direct.cl: the direct irradiance of the scene's lights at each query
 * point: DETP's option direct = "exact" (oclgi/estimators/detp_direct.py).
 *
 * detp_direct_add  one work-item per point: E_i += the delta lights' part,
 *                  exact, plus the other lights' part, sampled; added to
 *                  the irradiance the resolve wrote (float4 per point, xyz
 *                  = RGB).
 *
 * Delta lights (point, spot, IES, sun): one shadow ray per point and light,
 * I(d) cos(theta) / r^2 * V (point, spot, IES) or E_perp cos(theta) * V
 * (sun). The emitted intensity is the photons' own: a light's expected
 * power per solid angle along d is bound * light_pdf_dir(d) * profile(d)
 * (light.h samples d with light_pdf_dir and scales the photon's power by
 * the profile: a spot's or an IES spot's smoothstep), and the sun's
 * irradiance on a plane perpendicular to it is bound * its position
 * density (light_pdf_dir of the sun). ``bound`` (float4 per emitter, RGB)
 * is each light's bound on its photons' power, from the host. No
 * randomness.
 *
 * The other lights (area lights: emitting triangles; a uniform sky; an
 * environment map): E = integral over the hemisphere of L_e(w) cos dw, by
 * n_samples pairs of samples combined by multiple importance sampling
 * (Veach's one-sample-per-strategy estimator; pbrt-v4's and Mitsuba 3's
 * direct-light sampling does the same):
 *   light sample  an emitter by its power among these (spread_cdf: the
 *                 photons' choice restricted to them; the stratum's first
 *                 number picks it and, rescaled, goes on), then a point of the
 *                 triangle uniform by area (pdf r^2 / (A cos_l) in solid
 *                 angle), a direction of the sky uniform over its sphere or
 *                 hemisphere, or a texel of the map by its tables (light.h)
 *                 and a direction uniform in it; one shadow ray.
 *   BSDF sample   a cosine-distributed direction (pdf cos / pi, the
 *                 diffuse lobe); the surface it meets is an emitter's
 *                 front (tri_emitter) or the ray leaves to the sky.
 * Each sample's value f / p times its weight, w_l = p_l^2 / (p_l^2 + p_b^2)
 * for the light sample, w_b = p_b^2 / (p_l^2 + p_b^2) for the BSDF sample
 * (the power heuristic, mis = 0; the balance heuristic p / (p_l + p_b),
 * mis = 1; light samples alone, w_l = 1, mis = 2; BSDF samples alone,
 * mis = 3: oclgi/estimators/detp_direct.py MIS_MODES's order). Both
 * densities are evaluated for both samples, so w_l + w_b = 1 for every
 * direction either strategy can produce: unbiased. The radiance is the
 * lights' own: an area light's emission (spread_info.xyz), the sky's and
 * the map's as a camera ray sees them (background.h).
 *
 * Stratified: sample j < s^2 (s = floor(sqrt(n_samples))) takes cell
 * (j % s, j / s) of an s x s grid over its two main numbers (the point on
 * the triangle or the sky, the cosine direction), jittered. Random numbers:
 * rng.h keyed by the run's seed xor this kernel's constants, the point's
 * own key (a hash of its position's and normal's bits, so that the value
 * of a point depends on the point alone: not on its index, the other
 * points, the batch, the MPI rank or the work-group size), sample j as the
 * bounce, and blocks 0, 1 (light) and 2 (BSDF).
 *
 * Every shadow ray leaves the point eps along the point's normal, as the
 * tracer lifts a path's next segment off the surface (photon_trace.cl); a
 * light sample's target is lifted eps off its triangle, as a photon's
 * origin is. The lights are those of the current pose, so a session's
 * direct light is a fresh one's.
 */
#include "oclgi_types.h"
#include "background.h"
#include "bvh.h"
#include "light.h"
#include "rng.h"

#define DIRECT_SEED_LO 0x3C6EF372u
#define DIRECT_SEED_HI 0xA54FF53Au

#define DIRECT_ARGS __global const Emitter *emitters, __global const float *table,                    \
                    __global const float4 *spread_info, __global const float *spread_cdf,            \
                    __global const int *spread_ids, int n_spread, __global const int *tri_emitter,   \
                    int sky, __global const Background *bg, __global const float4 *bg_texels, int mis
#define DIRECT_PASS emitters, table, spread_info, spread_cdf, spread_ids, n_spread, tri_emitter, sky, bg, \
                    bg_texels, mis

/* The weight of a sample of density p drawn by its strategy, the other
 * strategy's density q. */
inline float direct_weight(float p, float q, int mis)
{
    if (mis >= 2) return 1.0f; /* one strategy alone */
    if (mis == 1) return p / (p + q);
    return (p * p) / (p * p + q * q);
}

/* A mix of the point's bits: its key in the random numbers. */
inline uint direct_point_key(float3 x, float3 n)
{
    uint h = 0x811C9DC5u;
    uint w[6] = {as_uint(x.x), as_uint(x.y), as_uint(x.z), as_uint(n.x), as_uint(n.y), as_uint(n.z)};
    for (int k = 0; k < 6; ++k) {
        h ^= w[k];
        h *= 0x01000193u;
        h ^= h >> 15;
        h *= 0x2C1B3C6Du;
        h ^= h >> 12;
    }
    return h;
}

/* The stratum of sample j in an s x s grid, jittered by (u, v). */
inline float2 direct_stratum(int j, int s, float u, float v)
{
    if (j >= s * s) return (float2)(u, v);
    return (float2)(((float)(j % s) + u) / (float)s, ((float)(j / s) + v) / (float)s);
}

/* The solid-angle density of the sky's light sample along w. */
inline float direct_sky_pdf(__global const Emitter *em, float3 w, __global const float *table)
{
    if (em->kind == OCLGI_EMITTER_ENVMAP) return light_envmap_pdf(em, w, table);
    if (em->b != 0.0f) return dot(w, vload3(0, em->e1)) > 0.0f ? 1.0f / (2.0f * OCLGI_PI) : 0.0f;
    return 1.0f / (4.0f * OCLGI_PI);
}

/* The solid-angle density of area light em's light sample at a point seen
 * at distance^2 r2 with cosine cos_l there (0 behind it). */
inline float direct_area_pdf(__global const Emitter *em, float r2, float cos_l)
{
    float area = 0.5f * length(cross(vload3(0, em->e1), vload3(0, em->e2)));
    return cos_l > 0.0f ? r2 / (area * cos_l) : 0.0f;
}

/* One light sample's f / p times its weight. */
inline float3 direct_light_sample(SCENE_ARGS, DIRECT_ARGS, float3 o, float3 n, float eps, uint s_lo, uint s_hi,
                                  uint key, int j, int s)
{
    float4 u = rng_uniform4(s_lo, s_hi, key, (uint)j, 0u);
    float2 v = direct_stratum(j, s, u.x, u.y);
    /* the emitter from the stratum's first number, which then goes on,
     * rescaled within the emitter's share, to place the sample: the strata
     * cover every emitter's samples, as they would one emitter's */
    int pick = light_pick(spread_cdf, n_spread, v.x);
    float lo = pick > 0 ? spread_cdf[pick - 1] : 0.0f, hi = spread_cdf[pick];
    v.x = fmin(hi > lo ? (v.x - lo) / (hi - lo) : u.z, 0x1.fffffep-1f);
    int k = spread_ids[pick];
    __global const Emitter *em = emitters + k;
    float3 w, le;
    float tmax = INFINITY, pdf;
    if (em->kind == OCLGI_EMITTER_TRIANGLE) {
        float3 e1 = vload3(0, em->e1), e2 = vload3(0, em->e2);
        float3 nl = normalize(cross(e1, e2));
        float su = sqrt(v.x);
        float3 y = vload3(0, em->p) + su * (1.0f - v.y) * e1 + su * v.y * e2 + eps * nl;
        float3 d = y - o;
        float r2 = dot(d, d);
        if (!(r2 > 0.0f)) return (float3)(0.0f);
        tmax = sqrt(r2);
        w = d / tmax;
        pdf = direct_area_pdf(em, r2, -dot(w, nl));
        le = spread_info[k].xyz;
    } else {
        if (em->kind == OCLGI_EMITTER_ENVMAP) {
            int W = (int)em->e2[0], H = (int)em->e2[1];
            __global const float *rows = table + em->tri, *cols = rows + H;
            int i = light_pick(rows, H, v.x);
            int c = light_pick(cols + i * W, W, v.y);
            float4 r = rng_uniform4(s_lo, s_hi, key, (uint)j, 1u);
            w = light_envmap_dir(i, c, W, H, r.x, r.y);
        } else if (em->b != 0.0f) { /* uniform over the hemisphere about up */
            w = light_dir_about(vload3(0, em->e1), v.x, v.y);
        } else {
            w = sample_sphere(v.x, v.y);
        }
        pdf = direct_sky_pdf(em, w, table);
        le = background_radiance(bg, bg_texels, w);
    }
    pdf *= spread_info[k].w;
    float c = dot(n, w);
    if (!(c > 0.0f) || !(pdf > 0.0f) || !(le.x > 0.0f || le.y > 0.0f || le.z > 0.0f)) return (float3)(0.0f);
    if (scene_any_hit(SCENE_PASS, o, w, tmax)) return (float3)(0.0f);
    return le * (c * direct_weight(pdf, c / OCLGI_PI, mis) / pdf);
}

/* One BSDF (cosine) sample's f / p times its weight. */
inline float3 direct_bsdf_sample(SCENE_ARGS, DIRECT_ARGS, float3 o, float3 n, uint s_lo, uint s_hi, uint key,
                                 int j, int s)
{
    float4 u = rng_uniform4(s_lo, s_hi, key, (uint)j, 2u);
    float2 v = direct_stratum(j, s, u.x, u.y);
    float3 w = sample_cosine(n, fmin(v.x, 0x1.fffffep-1f), v.y);
    float pb = dot(n, w) / OCLGI_PI;
    if (!(pb > 0.0f)) return (float3)(0.0f);
    Hit h;
    scene_closest_hit(SCENE_PASS, o, w, INFINITY, &h);
    float3 le;
    float pl;
    if (h.tri < 0) {
        if (sky < 0) return (float3)(0.0f);
        le = background_radiance(bg, bg_texels, w);
        pl = spread_info[sky].w * direct_sky_pdf(emitters + sky, w, table);
    } else {
        int k = tri_emitter[h.tri];
        if (k < 0) return (float3)(0.0f);
        __global const Emitter *em = emitters + k;
        float cos_l = -dot(w, normalize(cross(vload3(0, em->e1), vload3(0, em->e2))));
        if (!(cos_l > 0.0f)) return (float3)(0.0f); /* its back: one-sided */
        le = spread_info[k].xyz;
        pl = spread_info[k].w * direct_area_pdf(em, h.t * h.t, cos_l);
    }
    return le * (OCLGI_PI * direct_weight(pb, pl, mis)); /* L cos / (cos / pi) */
}

__kernel void detp_direct_add(SCENE_ARGS, DIRECT_ARGS, int n_emitters, __global const float4 *bound,
                              __global const float4 *positions, __global const float4 *normals,
                              int n_points, float eps, int n_samples, uint seed_lo, uint seed_hi,
                              __global float4 *irradiance)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    float3 x = positions[i].xyz, n = normals[i].xyz;
    n = normalize(n);
    float3 o = x + eps * n;
    float3 sum = (float3)(0.0f);
    for (int k = 0; k < n_emitters; ++k) {
        __global const Emitter *em = emitters + k;
        int kind = em->kind;
        float3 w, e;
        float tmax;
        if (kind == OCLGI_EMITTER_SUN) {
            float3 d = vload3(0, em->e1);
            w = -d;
            tmax = INFINITY;
            e = bound[k].xyz * light_pdf_dir(em, d, table);
        } else if (kind == OCLGI_EMITTER_POINT || kind == OCLGI_EMITTER_SPOT || kind == OCLGI_EMITTER_IES) {
            float3 v = vload3(0, em->p) - x; /* the light as seen from the point; the ray starts at o */
            float r2 = dot(v, v);
            if (!(r2 > 0.0f)) continue;
            float r = sqrt(r2);
            w = v / r;
            tmax = r;
            float3 d = -w;
            float profile = kind == OCLGI_EMITTER_POINT ? 1.0f : light_smoothstep(dot(d, vload3(0, em->e1)), em->a, em->b);
            e = bound[k].xyz * (light_pdf_dir(em, d, table) * profile / r2);
        } else {
            continue; /* area lights and skies: sampled below */
        }
        float c = dot(n, w);
        if (!(c > 0.0f) || !(e.x > 0.0f || e.y > 0.0f || e.z > 0.0f)) continue;
        if (!scene_any_hit(SCENE_PASS, o, w, tmax)) sum += e * c;
    }
    if (n_spread > 0 && n_samples > 0 && dot(n, n) > 0.0f) {
        uint s_lo = DIRECT_SEED_LO ^ seed_lo, s_hi = DIRECT_SEED_HI ^ seed_hi;
        uint key = direct_point_key(x, n);
        int s = (int)sqrt((float)n_samples);
        while ((s + 1) * (s + 1) <= n_samples) ++s;
        while (s * s > n_samples) --s;
        float3 spread = (float3)(0.0f);
        for (int j = 0; j < n_samples; ++j) {
            if (mis != 3) spread += direct_light_sample(SCENE_PASS, DIRECT_PASS, o, n, eps, s_lo, s_hi, key, j, s);
            if (mis != 2) spread += direct_bsdf_sample(SCENE_PASS, DIRECT_PASS, o, n, s_lo, s_hi, key, j, s);
        }
        sum += spread * (1.0f / (float)n_samples);
    }
    irradiance[i] += (float4)(sum, 0.0f);
}
