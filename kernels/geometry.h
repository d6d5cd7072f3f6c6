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

/* For the traversal loops' hot callees: PoCL's LLVM otherwise keeps
 * tri_intersect a call, and passing RayShear by value through the stack
 * stalls every test on a store-to-load forward (measured: 8% of a closest
 * hit's time). Inlining changes no arithmetic. */
#define HOT_INLINE inline __attribute__((always_inline))

typedef struct {
    int kx, ky, kz;   /* axes: kz the largest |d| component */
    float sx, sy, sz; /* shear constants */
    float3 d;         /* the direction itself, for the hit distance */
} RayShear;

HOT_INLINE float axis_of(float3 v, int k)
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

/* dot and cross with their operations written out, (x + y) + z: the
 * builtins are library code that FP_CONTRACT does not reach, and a GPU
 * driver's may fuse multiply-adds (NVIDIA's do), so tri_intersect and the
 * lane-wise tri4_intersect below would differ in the last bits there. */
HOT_INLINE float dot_exact(float3 a, float3 b)
{
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

HOT_INLINE float3 cross_exact(float3 a, float3 b)
{
    return (float3)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

/* Returns 1 and sets t and the barycentrics (u of v1, v of v2) when the ray
 * hits the triangle at 0 < t < tmax. */
HOT_INLINE int tri_intersect(float3 o, RayShear r, float3 v0, float3 v1, float3 v2,
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
    float3 n = cross_exact(v1 - v0, v2 - v0);
    float dn = dot_exact(r.d, n);
    float tt = dn != 0.0f ? dot_exact(a, n) / dn : (U * az + V * bz + W * cz) * r.sz * inv;
    if (!(tt > 0.0f && tt < tmax)) return 0;
    *t = tt;
    *u = V * inv;
    *v = W * inv;
    return 1;
}

HOT_INLINE float4 axis4_of(float4 x, float4 y, float4 z, int k)
{
    return k == 0 ? x : (k == 1 ? y : z);
}

HOT_INLINE float lane4_of(float4 v, int k)
{
    return k == 0 ? v.x : (k == 1 ? v.y : (k == 2 ? v.z : v.w));
}

/* tri_intersect on the first n (1..4) of 4 triangles at once: p points at
 * 9 float4, the x, y, z of v0, v1, v2 (oclgi_types.h TriBlock4), one
 * triangle per lane. Each lane computes exactly tri_intersect's operations
 * in the same order (dot_exact and cross_exact written out: (x + y) + z, no
 * fused multiply-add), so every triangle is accepted or
 * not, at the same t, u, v bits, as one at a time. Returns the lane of the
 * nearest accepted triangle, the lowest of equal t (the one a sequential
 * test in lane order keeps), or -1. */
HOT_INLINE int tri4_intersect(float3 o, RayShear r, __global const float4 *p, int n, float tmax,
                             float *t, float *u, float *v)
{
    float4 ax_ = p[0] - o.x, ay_ = p[1] - o.y, az_ = p[2] - o.z;
    float4 bx_ = p[3] - o.x, by_ = p[4] - o.y, bz_ = p[5] - o.z;
    float4 cx_ = p[6] - o.x, cy_ = p[7] - o.y, cz_ = p[8] - o.z;
    float4 az = axis4_of(ax_, ay_, az_, r.kz), bz = axis4_of(bx_, by_, bz_, r.kz), cz = axis4_of(cx_, cy_, cz_, r.kz);
    float4 ax = axis4_of(ax_, ay_, az_, r.kx) - r.sx * az, ay = axis4_of(ax_, ay_, az_, r.ky) - r.sy * az;
    float4 bx = axis4_of(bx_, by_, bz_, r.kx) - r.sx * bz, by = axis4_of(bx_, by_, bz_, r.ky) - r.sy * bz;
    float4 cx = axis4_of(cx_, cy_, cz_, r.kx) - r.sx * cz, cy = axis4_of(cx_, cy_, cz_, r.ky) - r.sy * cz;
    float4 U = cx * by - cy * bx;
    float4 V = ax * cy - ay * cx;
    float4 W = bx * ay - by * ax;
    int4 outside = ((U < 0.0f) | (V < 0.0f) | (W < 0.0f)) & ((U > 0.0f) | (V > 0.0f) | (W > 0.0f));
    float4 det = U + V + W;
    float4 inv = 1.0f / det;
    float4 e1x = p[3] - p[0], e1y = p[4] - p[1], e1z = p[5] - p[2];
    float4 e2x = p[6] - p[0], e2y = p[7] - p[1], e2z = p[8] - p[2];
    float4 nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
    float4 dn = r.d.x * nx + r.d.y * ny + r.d.z * nz;
    float4 tt = select((U * az + V * bz + W * cz) * r.sz * inv, (ax_ * nx + ay_ * ny + az_ * nz) / dn, dn != 0.0f);
    int4 ok = ~outside & (det != 0.0f) & (tt > 0.0f) & (tt < tmax) & ((int4)(0, 1, 2, 3) < n);
    if (!any(ok)) return -1;
    float4 tc = select((float4)(INFINITY), tt, ok);
    float m = fmin(fmin(tc.x, tc.y), fmin(tc.z, tc.w));
    int k = tc.x == m ? 0 : (tc.y == m ? 1 : (tc.z == m ? 2 : 3));
    float ik = lane4_of(inv, k);
    *t = m;
    *u = lane4_of(V, k) * ik;
    *v = lane4_of(W, k) * ik;
    return k;
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
