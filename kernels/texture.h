/* texture.h: albedo textures (oclgi/scene/textures.py packs them).
 *
 * albedo_tint  a material's albedo's texture and vertex colours at a point:
 *              the point's texture coordinates (and colours) from the point
 *              itself, through its triangle's affine maps (textures.uv_maps,
 *              colour_maps) applied in its object's space, so a photon's hit
 *              needs no barycentrics and a re-traced path textures bit for
 *              bit as its first trace did (both compute from the stored
 *              floats).
 * texture_rgb  bilinear lookup, repeating outside [0, 1), v up the image
 *              (row 0, the top, at v = 1); texel centres at (i + 0.5) / w.
 */
#ifndef OCLGI_TEXTURE_H
#define OCLGI_TEXTURE_H

#include "bvh.h"

#define TEXTURE_ARGS __global const float8 *tri_uvmap, __global const float4 *tri_colourmap,       \
                     __global const int *tri_object, __global const Texture *textures,         \
                     __global const float4 *texels
#define TEXTURE_PASS tri_uvmap, tri_colourmap, tri_object, textures, texels

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

/* What the albedo of material m is multiplied by at point p of triangle
 * tri: its texture's value there, and the triangle's vertex colours there
 * (each triangle's affine map from its plane to RGB, as for uv); 1 when it
 * has neither. */
inline float3 albedo_tint(TEXTURE_ARGS, __global const Instance *instances, __global const Material *m, int tri,
                          float3 p)
{
    float3 k = (float3)(1.0f);
    int colours = m->flags & OCLGI_MATERIAL_VERTEX_COLOUR;
    if (m->texture < 0 && !colours) return k;
    float3 q = xform_point(instances[tri_object[tri]].object_from_world, p);
    if (m->texture >= 0) {
        float8 t = tri_uvmap[tri];
        k = texture_rgb(TEXTURE_PASS, m->texture, (float2)(dot(t.s012, q) + t.s3, dot(t.s456, q) + t.s7));
    }
    if (colours) {
        __global const float4 *c = &tri_colourmap[3 * tri];
        k *= clamp((float3)(dot(c[0].xyz, q) + c[0].w, dot(c[1].xyz, q) + c[1].w, dot(c[2].xyz, q) + c[2].w),
                   0.0f, 1.0f);
    }
    return k;
}

/* The albedo of material m at point p of triangle tri (albedo_tint). */
inline float3 texture_albedo(TEXTURE_ARGS, __global const Instance *instances, __global const Material *m,
                             int tri, float3 p)
{
    return vload3(0, m->albedo) * albedo_tint(TEXTURE_PASS, instances, m, tri, p);
}

#endif
