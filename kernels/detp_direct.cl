/* detp_direct.cl: the direct irradiance of the scene's delta lights (point,
 * spot, IES, sun) at each query point, by one shadow ray per point and
 * light: DETP's option direct = "exact" (oclgi/estimators/detp_direct.py).
 *
 * detp_direct_add  one work-item per point: E_i += sum over the lights of
 *                  I(d) cos(theta) / r^2 * V (point, spot, IES) or
 *                  E_perp cos(theta) * V (sun), added to the irradiance the
 *                  resolve wrote (float4 per point, xyz = RGB).
 *
 * The emitted intensity is the photons' own: a light's expected power per
 * solid angle along d is bound * light_pdf_dir(d) * profile(d) (light.h
 * samples d with light_pdf_dir and scales the photon's power by the
 * profile: a spot's or an IES spot's smoothstep), and the sun's
 * irradiance on a plane perpendicular to it is bound * its position
 * density (light_pdf_dir of the sun). ``bound`` (float4 per emitter, RGB)
 * is each light's bound on its photons' power, from the host (the emitter
 * records hold it relative to the photon unit).
 *
 * The shadow ray leaves the point eps along the point's normal, as the
 * tracer lifts a path's next segment off the surface (photon_trace.cl),
 * and must reach the light (the sun: leave the scene) unoccluded; the
 * light's direction, distance and cosine are the point's own. No
 * randomness: a pure function of the point, the lights and the pose.
 */
#include "oclgi_types.h"
#include "bvh.h"
#include "light.h"

__kernel void detp_direct_add(SCENE_ARGS, __global const Emitter *emitters, int n_emitters,
                              __global const float *table, __global const float4 *bound,
                              __global const float4 *positions, __global const float4 *normals,
                              int n_points, float eps, __global float4 *irradiance)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    float3 x = positions[i].xyz, n = normals[i].xyz;
    n = normalize(n);
    float3 o = x + eps * n;
    float3 sum = (float3)(0.0f);
    for (int k = 0; k < n_emitters; ++k) {
        __global const Emitter *em = emitters + k;
        int kind = em->kind;
        float3 w, e;
        float tmax;
        if (kind == OCLGI_EMITTER_SUN) {
            float3 d = vload3(0, em->e1);
            w = -d;
            tmax = INFINITY;
            e = bound[k].xyz * light_pdf_dir(em, d, table);
        } else if (kind == OCLGI_EMITTER_POINT || kind == OCLGI_EMITTER_SPOT || kind == OCLGI_EMITTER_IES) {
            float3 v = vload3(0, em->p) - x; /* the light as seen from the point; the ray starts at o */
            float r2 = dot(v, v);
            if (!(r2 > 0.0f)) continue;
            float r = sqrt(r2);
            w = v / r;
            tmax = r;
            float3 d = -w;
            float profile = kind == OCLGI_EMITTER_POINT ? 1.0f : light_smoothstep(dot(d, vload3(0, em->e1)), em->a, em->b);
            e = bound[k].xyz * (light_pdf_dir(em, d, table) * profile / r2);
        } else {
            continue; /* area lights and skies: the host refuses them (their light comes by photons) */
        }
        float c = dot(n, w);
        if (!(c > 0.0f) || !(e.x > 0.0f || e.y > 0.0f || e.z > 0.0f)) continue;
        if (!scene_any_hit(SCENE_PASS, o, w, tmax)) sum += e * c;
    }
    irradiance[i] += (float4)(sum, 0.0f);
}
