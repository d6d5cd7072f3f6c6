/* bsdf.h: every material kind's scattering, the only place it is written.
 *
 * The four verbs of pbrt-v4's BxDF interface, switched on Material.kind
 * (oclgi_types.h; oclgi/scene/materials.py says what each kind reads):
 *
 *   bsdf_flags(m)                    MATERIAL_* flags (DELTA: single directions)
 *   bsdf_sample(m, n, wo, u, adjoint) a direction wi and its weight f |cos| / pdf
 *   bsdf_eval(m, n, wo, wi, adjoint)  f(wo, wi), without the cosine
 *   bsdf_pdf(m, n, wo, wi)            the density of bsdf_sample's wi (solid angle)
 *
 * n is the triangle's geometric normal as stored (its front side: the
 * outside of a dielectric); wo points away from the surface, back along
 * the ray that arrived (a photon's -d, a camera ray's -d), wi away from the
 * surface along the ray that leaves. `adjoint` is 1 for photons, which
 * carry power, and 0 for camera rays, which carry radiance: radiance is
 * scaled by (eta_i / eta_t)^2 through a refraction, power is not (Veach's
 * thesis, section 5.2).
 *
 * u is block 0 of the bounce's random numbers (rng.h). Sampling uses u.x,
 * u.y (the direction) and u.w (a lobe: diffuse or highlight, reflect or
 * refract); u.z is left to the caller's Russian roulette.
 *
 * Every kind's sample weight is at most 1 per channel for photons (the
 * fixed-point bound of oclgi_types.h): diffuse, albedo; mirror and
 * conductor, specular (x G1 <= 1); dielectrics, a tint (x G1); modified
 * Phong by the host's bound max(Kd) + max(Ks) (n + 2) / (n + 1) <= 1 with
 * lobes chosen in those proportions (materials.py).
 *
 * GGX (Trowbridge-Reitz) with Smith's separable masking G = G1(wo) G1(wi)
 * (Mitsuba 3's choice, so references agree), visible normals sampled as in
 * Heitz 2018, refraction as in Walter et al. 2007 with pbrt-v4's
 * generalised half vector.
 */
#ifndef OCLGI_BSDF_H
#define OCLGI_BSDF_H

#include "oclgi_types.h"
#include "geometry.h"

/* BsdfSample.flags: OCLGI_MATERIAL_DELTA when wi is a single direction,
 * and this bit when wi leaves by the other side of the surface. */
#define BSDF_TRANSMITTED 0x100

typedef struct {
    float3 wi;     /* unit, away from the surface */
    float3 weight; /* f |cos theta_i| / pdf; zero: absorbed */
    int flags;
} BsdfSample;

inline int bsdf_flags(__global const Material *m) { return m->flags; }

inline BsdfSample bsdf_absorbed(void)
{
    BsdfSample s;
    s.wi = (float3)(0.0f, 0.0f, 1.0f);
    s.weight = (float3)(0.0f);
    s.flags = 0;
    return s;
}

/* -- helpers ------------------------------------------------------------- */

inline float3 bsdf_reflect(float3 w, float3 n) { return 2.0f * dot(w, n) * n - w; }

/* Unpolarised Fresnel reflectance of a dielectric interface; cos_i >= 0 on
 * the incident side, eta = eta_t / eta_i; *cos_t receives the refracted
 * cosine (0 under total internal reflection, which returns 1). */
inline float bsdf_fresnel(float cos_i, float eta, float *cos_t)
{
    float sin2_t = (1.0f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0f) { *cos_t = 0.0f; return 1.0f; }
    float ct = sqrt(fmax(0.0f, 1.0f - sin2_t));
    *cos_t = ct;
    float rs = (cos_i - eta * ct) / (cos_i + eta * ct);
    float rp = (eta * cos_i - ct) / (eta * cos_i + ct);
    return 0.5f * (rs * rs + rp * rp);
}

/* w refracted through the plane of unit normal m (w and m on one side),
 * given cos_i = w.m, eta = eta_t / eta_i and the refracted cosine. */
inline float3 bsdf_refract(float3 w, float3 m, float cos_i, float eta, float cos_t)
{
    return normalize(-w / eta + (cos_i / eta - cos_t) * m);
}

/* GGX: the normal distribution D(m) and Smith's G1, in the local frame
 * (z along the normal). */
inline float ggx_d(float3 m, float alpha)
{
    if (m.z <= 0.0f) return 0.0f;
    float a2 = alpha * alpha;
    float t = m.z * m.z * (a2 - 1.0f) + 1.0f;
    return a2 / (OCLGI_PI * t * t);
}

inline float ggx_g1(float3 w, float3 m, float alpha)
{
    if (dot(w, m) * w.z <= 0.0f) return 0.0f; /* seen from the other side of m than of the surface */
    float z2 = w.z * w.z;
    float tan2 = fmax(0.0f, 1.0f - z2) / z2;
    return 2.0f / (1.0f + sqrt(1.0f + alpha * alpha * tan2));
}

/* A visible normal for wo (wo.z > 0), Heitz 2018. */
inline float3 ggx_sample_visible(float3 wo, float alpha, float u1, float u2)
{
    float3 vh = normalize((float3)(alpha * wo.x, alpha * wo.y, wo.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
    float3 t2 = cross(vh, t1);
    float r = sqrt(u1), phi = 2.0f * OCLGI_PI * u2;
    float p1 = r * cos(phi), p2 = r * sin(phi);
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * p2;
    float3 nh = p1 * t1 + p2 * t2 + sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
    return normalize((float3)(alpha * nh.x, alpha * nh.y, fmax(1e-7f, nh.z)));
}

/* The density of ggx_sample_visible's m. */
inline float ggx_pdf_visible(float3 wo, float3 m, float alpha)
{
    return ggx_g1(wo, m, alpha) * fmax(0.0f, dot(wo, m)) * ggx_d(m, alpha) / wo.z;
}

typedef struct { float3 t, b, n; } Frame;

inline Frame frame_of(float3 n)
{
    Frame f;
    f.n = n;
    onb(n, &f.t, &f.b);
    return f;
}
inline float3 to_local(Frame f, float3 v) { return (float3)(dot(v, f.t), dot(v, f.b), dot(v, f.n)); }
inline float3 to_world(Frame f, float3 v) { return v.x * f.t + v.y * f.b + v.z * f.n; }

/* The side a reflecting surface scatters on: n turned towards wo when it
 * has two sides; 0 when wo sees the black back of a one-sided surface. */
inline int bsdf_side(__global const Material *m, float3 n, float3 wo, float3 *ns)
{
    float c = dot(n, wo);
    *ns = n;
    if (c < 0.0f) {
        if (!(m->flags & OCLGI_MATERIAL_TWOSIDED)) return 0;
        *ns = -n;
    }
    return 1;
}

/* A dielectric's incident side: the normal on wo's side and eta_t / eta_i. */
inline float dielectric_side(__global const Material *m, float3 n, float3 wo, float3 *nn)
{
    int entering = dot(n, wo) >= 0.0f;
    *nn = entering ? n : -n;
    return entering ? m->ior : 1.0f / m->ior;
}

/* Modified Phong's lobe choice: diffuse with probability p_d / (p_d + p_s). */
inline float phong_p_diffuse(__global const Material *m)
{
    float3 kd = vload3(0, m->albedo), ks = vload3(0, m->specular);
    float n = m->exponent;
    float pd = fmax(kd.x, fmax(kd.y, kd.z));
    float ps = fmax(ks.x, fmax(ks.y, ks.z)) * (n + 2.0f) / (n + 1.0f);
    return pd + ps > 0.0f ? pd / (pd + ps) : 1.0f;
}

/* The highlight alone: *wi with cos^n alpha about the mirror direction of
 * wo (ns on wo's side), and its weight f_s cos / pdf_s = Ks (n + 2) /
 * (n + 1) cos theta_i, 0 below the surface. The camera follows it alone
 * (camera.cl: the diffuse lobe is estimated at the point). */
inline float3 phong_lobe_sample(__global const Material *m, float3 ns, float3 wo, float4 u, float3 *wi)
{
    float3 r = bsdf_reflect(wo, ns);
    float nexp = m->exponent;
    float ca = pow(u.x, 1.0f / (nexp + 1.0f));
    float sa = sqrt(fmax(0.0f, 1.0f - ca * ca)), phi = 2.0f * OCLGI_PI * u.y;
    Frame f = frame_of(r);
    *wi = normalize(to_world(f, (float3)(sa * cos(phi), sa * sin(phi), ca)));
    float ci = dot(ns, *wi);
    return ci > 0.0f ? vload3(0, m->specular) * ((nexp + 2.0f) / (nexp + 1.0f) * ci) : (float3)(0.0f);
}

/* -- the verbs ------------------------------------------------------------ */

inline float3 bsdf_eval(__global const Material *m, float3 n, float3 wo, float3 wi, int adjoint)
{
    if (m->flags & OCLGI_MATERIAL_DELTA) return (float3)(0.0f);
    if (m->kind == OCLGI_BSDF_ROUGH_DIELECTRIC) {
        float3 nn;
        float eta = dielectric_side(m, n, wo, &nn);
        Frame f = frame_of(nn);
        float3 o = to_local(f, wo), i = to_local(f, wi);
        if (o.z == 0.0f || i.z == 0.0f) return (float3)(0.0f);
        int reflect = i.z > 0.0f;
        float etap = reflect ? 1.0f : eta;
        float3 h = normalize(o + etap * i);
        if (h.z < 0.0f) h = -h;
        if (dot(h, i) * i.z < 0.0f || dot(h, o) * o.z < 0.0f) return (float3)(0.0f);
        float ct, F = bsdf_fresnel(fabs(dot(o, h)), eta, &ct);
        float alpha = m->roughness;
        float dg = ggx_d(h, alpha) * ggx_g1(o, h, alpha) * ggx_g1(i, h, alpha);
        if (reflect) return vload3(0, m->specular) * (F * dg / (4.0f * o.z * i.z));
        float denom = dot(i, h) + dot(o, h) / eta;
        float ft = (1.0f - F) * dg * fabs(dot(i, h) * dot(o, h) / (i.z * o.z * denom * denom));
        if (!adjoint) ft /= eta * eta;
        return vload3(0, m->albedo) * ft;
    }
    float3 ns;
    if (!bsdf_side(m, n, wo, &ns)) return (float3)(0.0f);
    float ci = dot(ns, wi), co = dot(ns, wo);
    if (ci <= 0.0f) return (float3)(0.0f);
    if (m->kind == OCLGI_BSDF_DIFFUSE) return vload3(0, m->albedo) * (1.0f / OCLGI_PI);
    if (m->kind == OCLGI_BSDF_PHONG) {
        float ca = fmax(0.0f, dot(bsdf_reflect(wo, ns), wi));
        float nexp = m->exponent;
        return vload3(0, m->albedo) * (1.0f / OCLGI_PI) +
               vload3(0, m->specular) * ((nexp + 2.0f) / (2.0f * OCLGI_PI) * pow(ca, nexp));
    }
    /* OCLGI_BSDF_CONDUCTOR */
    if (co <= 0.0f) return (float3)(0.0f);
    Frame f = frame_of(ns);
    float3 o = to_local(f, wo), i = to_local(f, wi);
    float3 h = normalize(o + i);
    float alpha = m->roughness;
    return vload3(0, m->specular) * (ggx_d(h, alpha) * ggx_g1(o, h, alpha) * ggx_g1(i, h, alpha) /
                                     (4.0f * o.z * i.z));
}

inline float bsdf_pdf(__global const Material *m, float3 n, float3 wo, float3 wi)
{
    if (m->flags & OCLGI_MATERIAL_DELTA) return 0.0f;
    if (m->kind == OCLGI_BSDF_ROUGH_DIELECTRIC) {
        float3 nn;
        float eta = dielectric_side(m, n, wo, &nn);
        Frame f = frame_of(nn);
        float3 o = to_local(f, wo), i = to_local(f, wi);
        if (o.z == 0.0f || i.z == 0.0f) return 0.0f;
        int reflect = i.z > 0.0f;
        float etap = reflect ? 1.0f : eta;
        float3 h = normalize(o + etap * i);
        if (h.z < 0.0f) h = -h;
        if (dot(h, i) * i.z < 0.0f || dot(h, o) * o.z < 0.0f) return 0.0f;
        float ct, F = bsdf_fresnel(fabs(dot(o, h)), eta, &ct);
        float pm = ggx_pdf_visible(o, h, m->roughness);
        if (reflect) return F * pm / (4.0f * fabs(dot(o, h)));
        float denom = dot(i, h) + dot(o, h) / eta;
        return (1.0f - F) * pm * fabs(dot(i, h)) / (denom * denom);
    }
    float3 ns;
    if (!bsdf_side(m, n, wo, &ns)) return 0.0f;
    float ci = dot(ns, wi);
    if (ci <= 0.0f) return 0.0f;
    if (m->kind == OCLGI_BSDF_DIFFUSE) return ci * (1.0f / OCLGI_PI);
    if (m->kind == OCLGI_BSDF_PHONG) {
        float pdiff = phong_p_diffuse(m);
        float ca = fmax(0.0f, dot(bsdf_reflect(wo, ns), wi));
        float nexp = m->exponent;
        return pdiff * ci * (1.0f / OCLGI_PI) +
               (1.0f - pdiff) * (nexp + 1.0f) / (2.0f * OCLGI_PI) * pow(ca, nexp);
    }
    if (dot(ns, wo) <= 0.0f) return 0.0f;
    Frame f = frame_of(ns);
    float3 o = to_local(f, wo), i = to_local(f, wi);
    float3 h = normalize(o + i);
    return ggx_pdf_visible(o, h, m->roughness) / (4.0f * dot(o, h));
}

inline BsdfSample bsdf_sample(__global const Material *m, float3 n, float3 wo, float4 u, int adjoint)
{
    BsdfSample s = bsdf_absorbed();
    int kind = m->kind;
    if (kind == OCLGI_BSDF_DIELECTRIC || kind == OCLGI_BSDF_ROUGH_DIELECTRIC) {
        float3 nn;
        float eta = dielectric_side(m, n, wo, &nn);
        float3 mn = nn;
        float alpha = m->roughness;
        Frame f;
        if (kind == OCLGI_BSDF_ROUGH_DIELECTRIC) {
            f = frame_of(nn);
            float3 o = to_local(f, wo);
            if (o.z <= 0.0f) return s;
            mn = to_world(f, ggx_sample_visible(o, alpha, u.x, u.y));
        }
        float ci = dot(wo, mn), ct;
        if (ci <= 0.0f) return s;
        float F = bsdf_fresnel(ci, eta, &ct);
        float3 tint;
        if (u.w < F) {
            s.wi = bsdf_reflect(wo, mn);
            if (dot(s.wi, nn) <= 0.0f) return bsdf_absorbed();
            tint = vload3(0, m->specular);
        } else {
            s.wi = bsdf_refract(wo, mn, ci, eta, ct);
            if (dot(s.wi, nn) >= 0.0f) return bsdf_absorbed();
            tint = vload3(0, m->albedo);
            if (!adjoint) tint /= eta * eta;
        }
        s.flags = u.w < F ? 0 : BSDF_TRANSMITTED;
        if (kind == OCLGI_BSDF_ROUGH_DIELECTRIC)
            tint *= ggx_g1(to_local(f, s.wi), to_local(f, mn), alpha);
        else
            s.flags |= OCLGI_MATERIAL_DELTA;
        s.weight = tint;
        return s;
    }
    float3 ns;
    if (!bsdf_side(m, n, wo, &ns)) return s;
    if (kind == OCLGI_BSDF_DIFFUSE) {
        s.wi = sample_cosine(ns, u.x, u.y);
        s.weight = vload3(0, m->albedo);
        return s;
    }
    if (kind == OCLGI_BSDF_MIRROR) {
        s.wi = bsdf_reflect(wo, ns);
        s.weight = vload3(0, m->specular);
        s.flags = OCLGI_MATERIAL_DELTA;
        return s;
    }
    if (kind == OCLGI_BSDF_PHONG) {
        float pdiff = phong_p_diffuse(m);
        if (u.w < pdiff)
            s.wi = sample_cosine(ns, u.x, u.y);
        else
            phong_lobe_sample(m, ns, wo, u, &s.wi);
        float ci = dot(ns, s.wi);
        float pdf = bsdf_pdf(m, n, wo, s.wi);
        if (ci <= 0.0f || !(pdf > 0.0f)) return bsdf_absorbed();
        s.weight = bsdf_eval(m, n, wo, s.wi, adjoint) * (ci / pdf);
        return s;
    }
    /* OCLGI_BSDF_CONDUCTOR */
    if (dot(ns, wo) <= 0.0f) return s;
    Frame f = frame_of(ns);
    float3 o = to_local(f, wo);
    float3 h = ggx_sample_visible(o, m->roughness, u.x, u.y);
    float3 i = bsdf_reflect(o, h);
    if (i.z <= 0.0f) return s;
    s.wi = normalize(to_world(f, i));
    s.weight = vload3(0, m->specular) * ggx_g1(i, h, m->roughness);
    return s;
}

#endif
