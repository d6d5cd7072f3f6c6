/* camera.cl: the visible point of each pixel, as DETP/Impact Count queries.
 *
 * camera_visible_points  one work-item per pixel of the rectangle x0, y0,
 *     rw x rh of a width x height image (row-major, top row first; outputs
 *     are the rectangle's pixels, row-major): a pinhole ray through the
 *     pixel's point `offset` (in pixel units from its top-left corner: 0.5,
 *     0.5 is the centre; a render of several samples per pixel launches
 *     once per sample, `sample` numbering them) against the instances given
 *     (all of them, or a subset: a session's static layer).
 *
 * The ray goes on through mirrors and glass, and samples the highlight of
 * glossy surfaces (bsdf.h, radiance mode), until it reaches a surface with
 * a diffuse part: that surface's point (w = as_float(tri)), its normal
 * turned towards the arriving ray (w = 1 when the triangle's own normal
 * faces it, which is when a one-sided emitter is seen): the geometric
 * normal, or the mesh's shading normal where it has vertex normals
 * (shading_normals.h), the point then lifted off the triangle by
 * lift * sin(angle between the two), lift the disc radius, so that the
 * turned disc lies wholly in front of its triangle (oclgi/scene/
 * shading_normals.py says why); the hit
 * barycentrics, and the weight the point's radiance is seen with (the
 * product of the sample weights on the way; 1 for a direct view). A
 * modified Phong surface is the point with probability p_d (its diffuse
 * lobe's share, bsdf.h phong_p_diffuse), weight / p_d, and otherwise
 * reflects through its highlight. A ray that leaves the scene (from the
 * eye, or after mirrors and glass) ends as tri = -1, position = its
 * direction (what background.h looks up), a zero normal (nothing is
 * estimated there) and weight (the path's weight, w = 1 when it met a
 * surface first: covered); a ray absorbed on the way, or still going past
 * OCLGI_CAMERA_MAX_DEPTH surfaces, sees black: weight (0, 0, 0, 1).
 *
 * first_in (not NULL): the first surface of each pixel of the width x
 * height image is where the instances given go on from (t, as_float(tri),
 * u, v: bvh.h scene_traverse_from), not from nothing: with first_in the
 * static layer's hits and the movable objects as the instances, a
 * session's re-traced pixels see what a ray through every object sees
 * (the static objects come first in every instance buffer), at the cost
 * of the movable objects' walk alone. first_out (not NULL): where each
 * pixel's first surface is written, to be that first_in.
 *
 * Random numbers: rng.h keyed by the camera's own seed, the pixel, and
 * sample * OCLGI_CAMERA_MAX_DEPTH + surface, so a pixel's path is the same
 * in every launch (the static layer and the composite of a session agree
 * wherever no moving object is met).
 */
#include "bsdf.h"
#include "bvh.h"
#include "rng.h"
#include "shading_normals.h"

#define CAMERA_SEED_LO 0x85EBCA6Bu
#define CAMERA_SEED_HI 0xC2B2AE35u

__kernel void camera_visible_points(SCENE_ARGS,
                                    __global const float4 *tri_normals, __global const int *tri_material,
                                    __global const Material *materials, __global const float4 *tri_shading,
                                    __global const int *tri_object, __global const Instance *poses,
                                    float4 eye, float4 forward, float4 right, float4 up,
                                    int width, int height, int x0, int y0, int rw, int rh, float2 offset,
                                    int sample, float eps, float lift,
                                    __global const float4 *first_in, __global float4 *first_out,
                                    __global float4 *positions, __global float4 *normals,
                                    __global float2 *barys, __global float4 *weights)
{
    int i = get_global_id(0);
    if (i >= rw * rh) return;
    int px = x0 + i % rw, py = y0 + i / rw;
    /* right and up are pre-scaled by the half-extents of the image plane */
    float sx = 2.0f * ((float)px + offset.x) / (float)width - 1.0f;
    float sy = 1.0f - 2.0f * ((float)py + offset.y) / (float)height;
    float3 o = eye.xyz;
    float3 d = normalize(forward.xyz + sx * right.xyz + sy * up.xyz);
    float3 weight = (float3)(1.0f);
    uint pixel = (uint)(py * width + px);
    for (int depth = 0; depth < OCLGI_CAMERA_MAX_DEPTH; ++depth) {
        Hit h;
        if (depth == 0 && first_in) {
            float4 f = first_in[pixel];
            h.t = f.x;
            h.tri = as_int(f.y);
            h.u = f.z;
            h.v = f.w;
            scene_traverse_from(SCENE_PASS, o, d, 0, &h);
        } else {
            h.u = h.v = 0.0f; /* what first_out holds for a miss */
            scene_closest_hit(SCENE_PASS, o, d, INFINITY, &h);
        }
        if (depth == 0 && first_out) first_out[pixel] = (float4)(h.t, as_float(h.tri), h.u, h.v);
        if (h.tri < 0) { /* left the scene along d: the background's */
            positions[i] = (float4)(d, as_float(-1));
            normals[i] = (float4)(0.0f);
            barys[i] = (float2)(0.0f);
            weights[i] = (float4)(weight, depth > 0 ? 1.0f : 0.0f);
            return;
        }
        float3 p = o + h.t * d;
        __global const Material *m = &materials[tri_material[h.tri]];
        float3 n = tri_normals[h.tri].xyz;
        float front = dot(n, d) < 0.0f ? 1.0f : 0.0f;
        float3 ns = front == 0.0f ? -n : n;
        float4 u = rng_uniform4(CAMERA_SEED_LO, CAMERA_SEED_HI, pixel,
                                (uint)(sample * OCLGI_CAMERA_MAX_DEPTH + depth), 0);
        int kind = m->kind;
        if (kind == OCLGI_BSDF_DIFFUSE || kind == OCLGI_BSDF_PHONG) {
            if (front == 0.0f && !(m->flags & OCLGI_MATERIAL_TWOSIDED)) break; /* a black back */
            float pd = kind == OCLGI_BSDF_PHONG ? phong_p_diffuse(m) : 1.0f;
            if (u.w < pd) {
                int smooth;
                float3 nsh = shading_normal(tri_shading, tri_object, poses, h.tri, p, ns, &smooth);
                if (smooth) p += (lift * length(cross(nsh, ns))) * ns; /* d sin(a): the disc in front */
                positions[i] = (float4)(p, as_float(h.tri));
                normals[i] = (float4)(nsh, front);
                barys[i] = (float2)(h.u, h.v);
                weights[i] = (float4)(weight / pd, 1.0f);
                return;
            }
            float3 wi;
            weight *= phong_lobe_sample(m, ns, -d, u, &wi) / (1.0f - pd);
            d = wi;
        } else {
            BsdfSample bs = bsdf_sample(m, n, -d, u, 0);
            weight *= bs.weight;
            d = bs.wi;
        }
        if (!(fmax(weight.x, fmax(weight.y, weight.z)) > 0.0f)) break;
        o = p + eps * (dot(d, ns) < 0.0f ? -ns : ns);
    }
    /* absorbed, or still on its way: covered, black */
    positions[i] = (float4)(0.0f, 0.0f, 0.0f, as_float(-1));
    normals[i] = (float4)(0.0f);
    barys[i] = (float2)(0.0f);
    weights[i] = (float4)(0.0f, 0.0f, 0.0f, 1.0f);
}
