/* surface_patches.cl: the distance from each point to the boundary of its
 * smooth surface patch, the geometric cap of adaptive DETP radii
 * (oclgi/estimators/surface_patches.py says what a patch and its boundary
 * are; the patches themselves are found on the host, once per scene).
 *
 * patch_boundary_distance  one work-item per point: the least distance
 *     from the point to the boundary edges of its triangle's patch
 *     (edges offsets[patch] .. offsets[patch + 1] - 1, two float4 ends
 *     each), INFINITY for a patch with no boundary (closed) or a point on
 *     no triangle (tri < 0). Each edge's distance is taken relative to its
 *     first end (p - a), so float32 keeps about 1e-7 of the scene's size.
 *     Every point walks all its patch's edges (a floor of 80 x 64 cells has
 *     288); on the host this was the adaptive radii's largest cost (about
 *     8 s for the 262,144 hits of 1,024 gather rays at 256 points).
 */

__kernel void patch_boundary_distance(__global const float4 *positions, __global const int *tri,
                                      __global const int *label, __global const int *offsets,
                                      __global const float4 *edges, int n_points, __global float *out)
{
    int i = get_global_id(0);
    if (i >= n_points) return;
    int t = tri[i];
    float best = INFINITY;
    if (t >= 0) {
        float3 p = positions[i].xyz;
        int patch = label[t];
        for (int e = offsets[patch]; e < offsets[patch + 1]; ++e) {
            float3 a = edges[2 * e].xyz, ab = edges[2 * e + 1].xyz - a;
            float3 ap = p - a;
            float len2 = dot(ab, ab);
            float s = len2 > 0.0f ? clamp(dot(ap, ab) / len2, 0.0f, 1.0f) : 0.0f;
            best = fmin(best, length(ap - s * ab));
        }
    }
    out[i] = best;
}
