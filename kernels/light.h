/* light.h: every emitter kind's emission, the only place a light is
 * sampled on the device (the host side is oclgi/scene/lights.py).
 *
 *   light_pick       the emitter of a uniform u from the power CDF.
 *   light_sample_le  a photon leaving emitter em: origin, direction and
 *                    power, from the emission event's random numbers r0, r1
 *                    (rng.h bounce 0, blocks 0 and 1: r0.x has chosen the
 *                    emitter; the kinds use r0.y, r0.z, r0.w, r1.x, and the
 *                    environment map r1.y, r1.z too). ``table`` is the
 *                    emitter CDF's buffer, which holds the environment
 *                    maps' tables after the CDF itself.
 *   light_envmap_pdf the density of an environment map's direction choice.
 *   light_pdf_dir    the density with which light_sample_le emits direction
 *                    d (and, for lights that sample a position, that
 *                    position): what multiple importance sampling of moving
 *                    lights weighs paths with.
 *
 * The kinds (Emitter fields, oclgi_types.h):
 *   TRIANGLE  area light: a uniform point of the triangle (p, e1, e2),
 *             lifted eps along its normal, a cosine-distributed direction on
 *             the normal's side (one-sided Lambertian).
 *   POINT     at p, uniform over the sphere.
 *   SPOT      at p, axis e1, uniform over the cone cos(theta) >= a (the
 *             cone's half-angle); the photon's power is scaled by pbrt-v4's
 *             SpotLight profile, smoothstep(a, b, cos theta), b = cos of the
 *             falloff start. The host's record power is the cone's full
 *             power, so the profile (<= 1) keeps every photon <= phi_max.
 *   SUN       direction of travel e1, from a disc of radius a perpendicular
 *             to it, centred at p - a e1: p and a are the scene's bounding
 *             sphere (the host's), so the disc lies outside it and its
 *             parallel rays cover everything in it.
 *   SKY       uniform radiance from every direction (b = 0) or from the
 *             hemisphere about up = e1 (b = 1): the photon travels along d,
 *             uniform over the sphere or over the half with d.up <= 0 (light
 *             coming down from the sky), from a disc of radius a
 *             perpendicular to d, centred at p - a d, as for the sun.
 *
 *   ENVMAP    an equirectangular map (Mitsuba's convention: column u,
 *             row v of a W x H map looks along w = (sin theta sin phi,
 *             cos theta, -sin theta cos phi), theta = pi v, phi = 2 pi u:
 *             row 0 is the zenith +y), as the sky but with the direction
 *             importance-sampled: a row from the marginal CDF (r0.w), a
 *             column from the row's CDF (r1.x), then uniform in the texel's
 *             solid angle (r1.y, r1.z). Texel probabilities are proportional
 *             to luminance x solid angle, so a photon's power varies only
 *             with the texel's colour: it carries power times the texel's
 *             g = rgb / (luminance M) <= 1 (M the map's largest rgb /
 *             luminance). tri: offset of its tables in ``table``: H row
 *             CDF values, H x W column CDFs, H x W x 3 g; e2 = (W, H, 0).
 *
 *   IES       a point (a = b = -1) or spot light with a tabulated profile
 *             (oclgi/scene/ies.py): at p, nadir e1, C = 0 along e2, C = 90
 *             along e2 x e1. tri: offset of its table in ``table``: V, H,
 *             the V + 1 vertical bin edges as -cos gamma (ascending), the
 *             H + 1 horizontal edges (radians, ascending), the V row CDF
 *             values, the V x H column CDFs. A bin from the row CDF (r0.y),
 *             one of its columns (r0.z), then uniform in cos gamma (r0.w)
 *             and in C (r1.x) within it: bins are chosen by candela x solid
 *             angle, so every photon carries the same power, times a spot's
 *             smoothstep(a, b, cos gamma) (the host's power is the flux of
 *             the bins that reach into the cone, unmasked: <= phi_max).
 *
 * Event 0's random numbers are used as they always were for the triangle
 * and point kinds, and with the same float operations in the same order,
 * so those photons are the same bit for bit as before this header.
 */
#ifndef OCLGI_LIGHT_H
#define OCLGI_LIGHT_H

#include "oclgi_types.h" /* first: geometry.h uses its OCLGI_PI */
#include "geometry.h"

typedef struct {
    float3 o, d, power; /* the photon's first segment: origin, direction, power */
} LightSample;

/* pbrt-v4's SmoothStep: 0 below a, 1 above b, 3t^2 - 2t^3 between. */
inline float light_smoothstep(float x, float a, float b)
{
    if (a == b) return x < a ? 0.0f : 1.0f;
    float t = clamp((x - a) / (b - a), 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

/* Direction with cosine z about n and azimuth 2 pi u. */
inline float3 light_dir_about(float3 n, float z, float u)
{
    float r = sqrt(fmax(0.0f, 1.0f - z * z));
    float phi = 2.0f * OCLGI_PI * u;
    float3 t, b;
    onb(n, &t, &b);
    return normalize(r * cos(phi) * t + r * sin(phi) * b + z * n);
}

/* A uniform point of the disc of radius R about c perpendicular to unit d. */
inline float3 light_disc_point(float3 c, float3 d, float R, float u, float v)
{
    float3 t, b;
    onb(d, &t, &b);
    float r = R * sqrt(u);
    float phi = 2.0f * OCLGI_PI * v;
    return c + r * cos(phi) * t + r * sin(phi) * b;
}

/* The first index k of cdf[0..n) with u < cdf[k] (cdf ascending, cdf[n-1] = 1 > u). */
inline int light_pick(__global const float *cdf, int n, float u)
{
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (u < cdf[mid]) hi = mid; else lo = mid + 1;
    }
    return lo;
}

/* Map direction (where the light comes from) of texel (i, j) at jitter (u, v). */
inline float3 light_envmap_dir(int i, int j, int W, int H, float u, float v)
{
    float ct = cos(OCLGI_PI * (float)i / (float)H), cb = cos(OCLGI_PI * (float)(i + 1) / (float)H);
    float y = ct + u * (cb - ct); /* uniform in cos theta: uniform in solid angle */
    float st = sqrt(fmax(0.0f, 1.0f - y * y));
    float phi = 2.0f * OCLGI_PI * ((float)j + v) / (float)W;
    return (float3)(st * sin(phi), y, -st * cos(phi));
}

/* The bin k of x in ascending edges[0..n] (edges[k] <= x < edges[k + 1],
 * clamped to 0..n-1), by bisection. */
inline int light_bin(__global const float *edges, int n, float x)
{
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (x >= edges[mid]) lo = mid; else hi = mid - 1;
    }
    return lo;
}

/* An IES light's direction of cos gamma z and horizontal angle phi in its
 * frame (nadir, C0, C90 = C0 x nadir). */
inline float3 light_ies_dir(__global const Emitter *em, float z, float phi)
{
    float3 nadir = vload3(0, em->e1), c0 = vload3(0, em->e2);
    float st = sqrt(fmax(0.0f, 1.0f - z * z));
    return normalize(st * cos(phi) * c0 + st * sin(phi) * cross(c0, nadir) + z * nadir);
}

/* The solid-angle density with which an environment map's tables pick
 * the direction w the light comes from (its texel's probability over the
 * texel's solid angle). */
inline float light_envmap_pdf(__global const Emitter *em, float3 w, __global const float *table)
{
    int W = (int)em->e2[0], H = (int)em->e2[1];
    __global const float *rows = table + em->tri, *cols = rows + H;
    float v = acos(clamp(w.y, -1.0f, 1.0f)) / OCLGI_PI;
    float u = atan2(w.x, -w.z) / (2.0f * OCLGI_PI);
    u -= floor(u);
    int i = min((int)(v * (float)H), H - 1), j = min((int)(u * (float)W), W - 1);
    float p_row = rows[i] - (i > 0 ? rows[i - 1] : 0.0f);
    __global const float *c = cols + i * W;
    float p_col = c[j] - (j > 0 ? c[j - 1] : 0.0f);
    float ct = cos(OCLGI_PI * (float)i / (float)H), cb = cos(OCLGI_PI * (float)(i + 1) / (float)H);
    float omega = 2.0f * OCLGI_PI / (float)W * (ct - cb); /* the texel's solid angle */
    return p_row * p_col / omega;
}

inline LightSample light_sample_le(__global const Emitter *em, float4 r0, float4 r1, float eps,
                                   __global const float *table)
{
    LightSample s;
    s.power = vload3(0, em->power);
    int kind = em->kind;
    if (kind == OCLGI_EMITTER_TRIANGLE) {
        float3 e1 = vload3(0, em->e1), e2 = vload3(0, em->e2);
        float3 n = normalize(cross(e1, e2));
        float su = sqrt(r0.y);
        s.o = vload3(0, em->p) + su * (1.0f - r0.z) * e1 + su * r0.z * e2 + eps * n;
        s.d = sample_cosine(n, r0.w, r1.x);
    } else if (kind == OCLGI_EMITTER_POINT) {
        s.o = vload3(0, em->p);
        s.d = sample_sphere(r0.y, r0.z);
    } else if (kind == OCLGI_EMITTER_SPOT) {
        float3 axis = vload3(0, em->e1);
        float z = 1.0f - r0.y * (1.0f - em->a); /* uniform in cos over [a, 1] */
        s.o = vload3(0, em->p);
        s.d = light_dir_about(axis, z, r0.z);
        s.power *= light_smoothstep(dot(s.d, axis), em->a, em->b);
    } else if (kind == OCLGI_EMITTER_IES) {
        __global const float *t = table + em->tri;
        int V = (int)t[0], H = (int)t[1];
        __global const float *vz = t + 2, *ph = vz + V + 1, *rows = ph + H + 1, *cols = rows + V;
        int i = light_pick(rows, V, r0.y);
        int j = light_pick(cols + i * H, H, r0.z);
        float z = -(vz[i] + r0.w * (vz[i + 1] - vz[i])); /* uniform in cos gamma: uniform in solid angle */
        s.o = vload3(0, em->p);
        s.d = light_ies_dir(em, z, ph[j] + r1.x * (ph[j + 1] - ph[j]));
        s.power *= light_smoothstep(z, em->a, em->b);
    } else {
        float3 d;
        if (kind == OCLGI_EMITTER_SUN) {
            d = vload3(0, em->e1);
        } else if (kind == OCLGI_EMITTER_ENVMAP) {
            int W = (int)em->e2[0], H = (int)em->e2[1];
            __global const float *rows = table + em->tri, *cols = rows + H, *g = cols + H * W;
            int i = light_pick(rows, H, r0.w);
            int j = light_pick(cols + i * W, W, r1.x);
            d = -light_envmap_dir(i, j, W, H, r1.y, r1.z);
            s.power *= vload3(i * W + j, g);
        } else if (em->b != 0.0f) { /* upper-hemisphere sky: down-going directions only */
            d = light_dir_about(-vload3(0, em->e1), r0.w, r1.x);
        } else {
            d = sample_sphere(r0.w, r1.x);
        }
        float R = em->a;
        s.o = light_disc_point(vload3(0, em->p) - R * d, d, R, r0.y, r0.z);
        s.d = d;
    }
    return s;
}

/* The density of emitting along d (unit) from em, as light_sample_le does:
 * solid-angle density for the point and spot kinds; for the kinds that
 * sample a position too, position density (per m^2) times direction
 * density (per sr). The sun's direction is a delta: its value is the
 * position density alone, the delta implied (pbrt-v3's
 * DistantLight::Pdf_Le gives the same pdfPos, and pdfDir = 0 for the
 * delta). Returns 0 for directions the light does not emit. */
inline float light_pdf_dir(__global const Emitter *em, float3 d, __global const float *table)
{
    int kind = em->kind;
    if (kind == OCLGI_EMITTER_TRIANGLE) {
        float3 c = cross(vload3(0, em->e1), vload3(0, em->e2));
        float len = length(c);
        float cos_t = dot(d, c) / len;
        return cos_t > 0.0f ? (2.0f / len) * cos_t / OCLGI_PI : 0.0f; /* 1 / area * cos / pi */
    }
    if (kind == OCLGI_EMITTER_POINT) return 1.0f / (4.0f * OCLGI_PI);
    if (kind == OCLGI_EMITTER_SPOT) {
        float cos_t = dot(d, vload3(0, em->e1));
        return cos_t >= em->a ? 1.0f / (2.0f * OCLGI_PI * (1.0f - em->a)) : 0.0f;
    }
    if (kind == OCLGI_EMITTER_IES) {
        __global const float *t = table + em->tri;
        int V = (int)t[0], H = (int)t[1];
        __global const float *vz = t + 2, *ph = vz + V + 1, *rows = ph + H + 1, *cols = rows + V;
        float3 nadir = vload3(0, em->e1), c0 = vload3(0, em->e2);
        float mz = -dot(d, nadir);
        if (mz < vz[0] || mz > vz[V]) return 0.0f; /* outside the profile's vertical range */
        float phi = atan2(dot(d, cross(c0, nadir)), dot(d, c0));
        phi -= 2.0f * OCLGI_PI * floor((phi - ph[0]) / (2.0f * OCLGI_PI)); /* into [ph[0], ph[0] + 2 pi) */
        int i = light_bin(vz, V, mz), j = light_bin(ph, H, phi);
        float p_row = rows[i] - (i > 0 ? rows[i - 1] : 0.0f);
        __global const float *c = cols + i * H;
        float p_col = c[j] - (j > 0 ? c[j - 1] : 0.0f);
        float omega = (vz[i + 1] - vz[i]) * (ph[j + 1] - ph[j]); /* the bin's solid angle */
        return omega > 0.0f ? p_row * p_col / omega : 0.0f;
    }
    float pdf_pos = 1.0f / (OCLGI_PI * em->a * em->a);
    if (kind == OCLGI_EMITTER_SUN) return pdf_pos;
    if (kind == OCLGI_EMITTER_ENVMAP) return pdf_pos * light_envmap_pdf(em, -d, table);
    if (em->b != 0.0f) return dot(d, vload3(0, em->e1)) <= 0.0f ? pdf_pos / (2.0f * OCLGI_PI) : 0.0f;
    return pdf_pos / (4.0f * OCLGI_PI);
}

#endif
