/* texture.h: albedo textures (oclgi/scene/textures.py packs them).
 *
 * texture_uv   a point's texture coordinates on triangle tri, from the
 *              point itself: the triangle's affine map (textures.uv_maps)
 *              applied in its object's space, so a photon's hit needs no
 *              barycentrics and a re-traced path textures bit for bit as
 *              its first trace did (both compute from the stored floats).
 * texture_rgb  bilinear lookup, repeating outside [0, 1), v up the image
 *              (row 0, the top, at v = 1); texel centres at (i + 0.5) / w.
 */
#ifndef OCLGI_TEXTURE_H
#define OCLGI_TEXTURE_H

#include "bvh.h"

#define TEXTURE_ARGS __global const float8 *tri_uvmap, __global const int *tri_object, \
                     __global const Texture *textures, __global const float4 *texels
#define TEXTURE_PASS tri_uvmap, tri_object, textures, texels

inline float2 texture_uv(TEXTURE_ARGS, __global const Instance *instances, int tri, float3 p)
{
    float3 q = xform_point(instances[tri_object[tri]].object_from_world, p);
    float8 m = tri_uvmap[tri];
    return (float2)(dot(m.s012, q) + m.s3, dot(m.s456, q) + m.s7);
}

inline float4 texel_at(__global const Texture *t, __global const float4 *texels, int x, int y)
{
    x %= t->width;
    y %= t->height;
    if (x < 0) x += t->width;
    if (y < 0) y += t->height;
    return texels[t->offset + y * t->width + x];
}

inline float3 texture_rgb(TEXTURE_ARGS, int id, float2 uv)
{
    __global const Texture *t = &textures[id];
    float fx = (uv.x - floor(uv.x)) * (float)t->width - 0.5f;
    float fy = (1.0f - (uv.y - floor(uv.y))) * (float)t->height - 0.5f;
    float x0 = floor(fx), y0 = floor(fy);
    float ax = fx - x0, ay = fy - y0;
    int ix = (int)x0, iy = (int)y0;
    float4 c = (1.0f - ay) * ((1.0f - ax) * texel_at(t, texels, ix, iy) + ax * texel_at(t, texels, ix + 1, iy)) +
               ay * ((1.0f - ax) * texel_at(t, texels, ix, iy + 1) + ax * texel_at(t, texels, ix + 1, iy + 1));
    return c.xyz;
}

/* The albedo of material m at point p of triangle tri: its own, times its
 * texture's value there when it has one. */
inline float3 texture_albedo(TEXTURE_ARGS, __global const Instance *instances, __global const Material *m,
                             int tri, float3 p)
{
    float3 a = vload3(0, m->albedo);
    if (m->texture < 0) return a;
    return a * texture_rgb(TEXTURE_PASS, m->texture, texture_uv(TEXTURE_PASS, instances, tri, p));
}

#endif
