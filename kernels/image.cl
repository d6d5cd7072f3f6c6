/* image.cl: radiance from irradiance, and tone mapping.
 *
 * image_shade     one work-item per pixel: L = weight * (Le (when the
 *                 emitter's front is seen) + albedo * E / pi), weight the
 *                 camera path's (camera.cl: 1 for a direct view, the
 *                 mirrors' and glass's on the way, 0 for a ray lost); a
 *                 ray that left the scene (tri = -1) sees the background
 *                 (background.h) along its direction, times its weight;
 *                 alpha is 1 where it met a surface, and everywhere when
 *                 the background has radiance (a sky is part of the image). The albedo (textured) times
 *                 the weight goes to `albedo` (the render's albedo layer).
 * image_tonemap   one work-item per pixel: exposure, the view transform
 *                 (view_transform.h: clamp and sRGB encoding, AgX or
 *                 filmic), 8 bits per channel; alpha is the coverage (radiance.w:
 *                 1 where a sample hit geometry, 0 on the background,
 *                 between for a pixel's averaged samples).
 */
#include "background.h"
#include "texture.h"
#include "view_transform.h"

__kernel void image_shade(__global const float4 *positions, __global const float4 *normals,
                          __global const float4 *irradiance, __global const int *tri_material,
                          __global const Material *materials, __global const float4 *weights,
                          __global const Instance *instances, TEXTURE_ARGS,
                          __global const Background *background, __global const float4 *bg_texels, int n,
                          __global float4 *radiance, __global float4 *albedo)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int t = as_int(positions[i].w);
    if (t < 0) {
        float4 w = weights[i];
        float3 L = w.xyz * background_radiance(background, bg_texels, positions[i].xyz);
        radiance[i] = (float4)(L, background->kind >= 0 ? 1.0f : w.w);
        albedo[i] = (float4)(0.0f);
        return;
    }
    __global const Material *m = &materials[tri_material[t]];
    float3 a = texture_albedo(TEXTURE_PASS, instances, m, t, positions[i].xyz);
    float3 L = a * irradiance[i].xyz * (1.0f / OCLGI_PI);
    if (normals[i].w > 0.5f) L += vload3(0, m->emission);
    radiance[i] = (float4)(L * weights[i].xyz, 1.0f);
    albedo[i] = (float4)(a * weights[i].xyz, 0.0f);
}

__kernel void image_tonemap(__global const float4 *radiance, int n, float exposure, int view,
                            __global uchar4 *pixels)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float3 d = view_transform(radiance[i].xyz * exposure, view);
    pixels[i] = (uchar4)(convert_uchar_sat_rte(255.0f * d.x), convert_uchar_sat_rte(255.0f * d.y),
                         convert_uchar_sat_rte(255.0f * d.z), convert_uchar_sat_rte(255.0f * radiance[i].w));
}
