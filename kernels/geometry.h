/* geometry.h: ray-triangle intersection, frames and direction sampling. */
#ifndef OCLGI_GEOMETRY_H
#define OCLGI_GEOMETRY_H

/* Watertight ray-triangle intersection (Woop, Benthin & Wald 2013).
 *
 * The ray is sheared so that it runs along +z; a triangle's vertices are
 * then tested with 2-D edge functions. The edge function of an edge depends
 * only on its two vertices and the ray, so two triangles sharing an edge
 * compute it identically (no FMA contraction: FP_CONTRACT OFF), and a ray
 * through the edge hits at least one of them: no light leaks between
 * triangles. Both faces count (surfaces are two-sided). The shear depends
 * only on the ray: compute it once with ray_shear. */
#pragma OPENCL FP_CONTRACT OFF

typedef struct {
    int kx, ky, kz;   /* axes: kz the largest |d| component */
    float sx, sy, sz; /* shear constants */
    float3 d;         /* the direction itself, for the hit distance */
} RayShear;

inline float axis_of(float3 v, int k)
{
    return k == 0 ? v.x : (k == 1 ? v.y : v.z);
}

inline RayShear ray_shear(float3 d)
{
    RayShear r;
    float3 ad = fabs(d);
    r.kz = ad.x > ad.y ? (ad.x > ad.z ? 0 : 2) : (ad.y > ad.z ? 1 : 2);
    r.kx = r.kz == 2 ? 0 : r.kz + 1;
    r.ky = r.kx == 2 ? 0 : r.kx + 1;
    float dz = axis_of(d, r.kz);
    if (dz < 0.0f) { int k = r.kx; r.kx = r.ky; r.ky = k; } /* keep the winding */
    r.sx = axis_of(d, r.kx) / dz;
    r.sy = axis_of(d, r.ky) / dz;
    r.sz = 1.0f / dz;
    r.d = d;
    return r;
}

/* Returns 1 and sets t and the barycentrics (u of v1, v of v2) when the ray
 * hits the triangle at 0 < t < tmax. */
inline int tri_intersect(float3 o, RayShear r, float3 v0, float3 v1, float3 v2,
                         float tmax, float *t, float *u, float *v)
{
    float3 a = v0 - o, b = v1 - o, c = v2 - o;
    float az = axis_of(a, r.kz), bz = axis_of(b, r.kz), cz = axis_of(c, r.kz);
    float ax = axis_of(a, r.kx) - r.sx * az, ay = axis_of(a, r.ky) - r.sy * az;
    float bx = axis_of(b, r.kx) - r.sx * bz, by = axis_of(b, r.ky) - r.sy * bz;
    float cx = axis_of(c, r.kx) - r.sx * cz, cy = axis_of(c, r.ky) - r.sy * cz;
    float U = cx * by - cy * bx;
    float V = ax * cy - ay * cx;
    float W = bx * ay - by * ax;
    if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return 0;
    float det = U + V + W;
    if (det == 0.0f) return 0;
    float inv = 1.0f / det;
    /* The sheared-frame distance (U az + V bz + W cz) sz / det loses digits
     * when the triangle is large or far against t (up to 1e-3 relative on
     * Sponza's floors); the plane equation in the ray's own frame keeps
     * them. Inside/outside stays the watertight decision above. */
    float3 n = cross(v1 - v0, v2 - v0);
    float dn = dot(r.d, n);
    float tt = dn != 0.0f ? dot(a, n) / dn : (U * az + V * bz + W * cz) * r.sz * inv;
    if (!(tt > 0.0f && tt < tmax)) return 0;
    *t = tt;
    *u = V * inv;
    *v = W * inv;
    return 1;
}

/* Orthonormal basis around a unit normal (Duff et al. 2017, branchless). */
inline void onb(float3 n, float3 *t, float3 *b)
{
    float s = copysign(1.0f, n.z);
    float a = -1.0f / (s + n.z);
    float c = n.x * n.y * a;
    *t = (float3)(1.0f + s * n.x * n.x * a, s * c, -s * n.x);
    *b = (float3)(c, s + n.y * n.y * a, -n.y);
}

/* Cosine-weighted direction about n (Malley: disc sample lifted). */
inline float3 sample_cosine(float3 n, float u1, float u2)
{
    float r = sqrt(u1);
    float phi = 2.0f * OCLGI_PI * u2;
    float3 t, b;
    onb(n, &t, &b);
    float z = sqrt(fmax(0.0f, 1.0f - u1));
    return normalize(r * cos(phi) * t + r * sin(phi) * b + z * n);
}

inline float3 sample_sphere(float u1, float u2)
{
    float z = 1.0f - 2.0f * u1;
    float r = sqrt(fmax(0.0f, 1.0f - z * z));
    float phi = 2.0f * OCLGI_PI * u2;
    return (float3)(r * cos(phi), r * sin(phi), z);
}

#endif
