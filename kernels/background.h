/* background.h: the radiance a camera ray sees when it leaves the scene
 * along unit direction d: a uniform sky's (above its horizon when it is a
 * hemisphere), an environment map's texel (nearest, Mitsuba's
 * equirectangular convention as in light.h: column u, row v look along
 * (sin theta sin phi, cos theta, -sin theta cos phi), theta = pi v, phi =
 * 2 pi u), or black. The sun is a direction, never seen. */
#ifndef OCLGI_BACKGROUND_H
#define OCLGI_BACKGROUND_H

#include "oclgi_types.h"

inline float3 background_radiance(__global const Background *bg, __global const float4 *texels, float3 d)
{
    if (bg->kind == OCLGI_EMITTER_SKY) {
        if (bg->hemisphere && !(dot(d, vload3(0, bg->up)) > 0.0f)) return (float3)(0.0f);
        return vload3(0, bg->radiance);
    }
    if (bg->kind == OCLGI_EMITTER_ENVMAP) {
        int W = bg->width, H = bg->height;
        float v = acos(clamp(d.y, -1.0f, 1.0f)) / OCLGI_PI;
        float u = atan2(d.x, -d.z) / (2.0f * OCLGI_PI);
        u -= floor(u);
        int i = min((int)(v * (float)H), H - 1), j = min((int)(u * (float)W), W - 1);
        return texels[bg->offset + i * W + j].xyz;
    }
    return (float3)(0.0f);
}

#endif
