/* view_transform.h: scene-referred radiance (times the exposure) to
 * display-encoded values in [0, 1], by view (oclgi/cl/constants.py VIEW_*;
 * tests/test_view_transform.py holds a float64 reference of each).
 *
 * srgb    clamp to [0, 1], then the sRGB encoding (IEC 61966-2-1): what
 *         oclgi always did, kept bit for bit (highlights clip).
 * agx     Troy Sobotka's AgX (github.com/sobotka/AgX), in the form most
 *         renderers use (Blender's AgX base, as fitted by Benjamin Wrensch's
 *         "Minimal AgX implementation", iolite-engine.com, 2024): the inset
 *         matrix (Rec. 709 primaries pulled towards white, so that bright
 *         saturated colours desaturate instead of skewing), log2 encoding
 *         over [-12.47393, 4.026069] stops around 0.18, the 6th-order
 *         polynomial fit of AgX's default-contrast sigmoid, and the outset
 *         matrix (the inset's inverse). The sigmoid's output is already
 *         display-encoded (about a 2.2 power), so no sRGB encoding follows.
 * filmic  Krzysztof Narkowicz's fit of ACES's RRT + sRGB ODT
 *         ("ACES Filmic Tone Mapping Curve", 2016): x (2.51 x + 0.03) /
 *         (x (2.43 x + 0.59) + 0.14) per channel, pre-exposed so that 1 maps
 *         to about 0.8 (the post: multiply by 0.6 for ACES's own exposure),
 *         a linear display value, then the sRGB encoding.
 */
#ifndef OCLGI_VIEW_TRANSFORM_H
#define OCLGI_VIEW_TRANSFORM_H

#include "constants.h"

inline float srgb_encode(float c)
{
    c = clamp(c, 0.0f, 1.0f);
    return c <= 0.0031308f ? 12.92f * c : 1.055f * pow(c, 1.0f / 2.4f) - 0.055f;
}

inline float3 srgb_encode3(float3 c)
{
    return (float3)(srgb_encode(c.x), srgb_encode(c.y), srgb_encode(c.z));
}

#define AGX_MIN_EV (-12.47393f)
#define AGX_MAX_EV 4.026069f

inline float3 agx_sigmoid(float3 x)
{
    float3 x2 = x * x, x4 = x2 * x2;
    return 15.5f * x4 * x2 - 40.14f * x4 * x + 31.96f * x4 - 6.868f * x2 * x + 0.4298f * x2 + 0.1191f * x - 0.00232f;
}

inline float3 view_agx(float3 c)
{
    /* inset: rows of the matrix applied to (r, g, b) */
    float3 v = (float3)(0.842479062253094f * c.x + 0.0784335999999992f * c.y + 0.0792237451477643f * c.z,
                        0.0423282422610123f * c.x + 0.878468636469772f * c.y + 0.0791661274605434f * c.z,
                        0.0423756549057051f * c.x + 0.0784336f * c.y + 0.879142973793104f * c.z);
    v = clamp(log2(fmax(v, (float3)(1e-10f))), AGX_MIN_EV, AGX_MAX_EV);
    v = agx_sigmoid((v - AGX_MIN_EV) / (AGX_MAX_EV - AGX_MIN_EV));
    /* outset */
    float3 o = (float3)(1.19687900512017f * v.x - 0.0980208811401368f * v.y - 0.0990297440797205f * v.z,
                        -0.0528968517574562f * v.x + 1.15190312990417f * v.y - 0.0989611768448433f * v.z,
                        -0.0529716355144438f * v.x - 0.0980434501171241f * v.y + 1.15107367264116f * v.z);
    return clamp(o, 0.0f, 1.0f);
}

inline float3 view_filmic(float3 c)
{
    float3 x = fmax(c, (float3)(0.0f));
    return srgb_encode3((x * (2.51f * x + 0.03f)) / (x * (2.43f * x + 0.59f) + 0.14f));
}

inline float3 view_transform(float3 c, int view)
{
    if (view == OCLGI_VIEW_AGX) return view_agx(c);
    if (view == OCLGI_VIEW_FILMIC) return view_filmic(c);
    return srgb_encode3(c);
}

#endif
