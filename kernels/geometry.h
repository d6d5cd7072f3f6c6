/* geometry.h: ray-triangle intersection, frames and direction sampling. */
#ifndef OCLGI_GEOMETRY_H
#define OCLGI_GEOMETRY_H

/* Moller-Trumbore. Returns 1 and sets t, u, v when the ray hits the
 * triangle at 0 < t < tmax; both faces count (surfaces are two-sided). */
inline int tri_intersect(float3 o, float3 d, float3 v0, float3 e1, float3 e2,
                         float tmax, float *t, float *u, float *v)
{
    float3 p = cross(d, e2);
    float det = dot(e1, p);
    if (fabs(det) < 1e-12f) return 0;
    float inv = 1.0f / det;
    float3 s = o - v0;
    float uu = dot(s, p) * inv;
    if (uu < 0.0f || uu > 1.0f) return 0;
    float3 q = cross(s, e1);
    float vv = dot(d, q) * inv;
    if (vv < 0.0f || uu + vv > 1.0f) return 0;
    float tt = dot(e2, q) * inv;
    if (!(tt > 0.0f && tt < tmax)) return 0;
    *t = tt; *u = uu; *v = vv;
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
