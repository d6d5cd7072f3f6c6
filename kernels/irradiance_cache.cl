/* irradiance_cache.cl: a render's indirect light gathered at a sparse grid
 * of its points and interpolated to the others
 * (oclgi/estimators/irradiance_cache.py says why and what is traded).
 *
 * The points are a camera's, one image of height x width per sample per
 * pixel, stacked (point i: pixel x = i % width, row y = (i / width) %
 * height). The records are sample 0's points at every spacing-th pixel
 * each way (grid cell (gy, gx) = pixel (gy s, gx s); cells[gy * gw + gx]
 * the record's index, -1 where that pixel sees nothing) and the points no
 * grid record can stand for (``own``: their record's index, else -1).
 *
 * A point's estimate from the 4 x 4 grid records around its pixel is the
 * weighted mean of their indirect irradiance, each weighted by
 *     a tent in the image, 1 - |d| / (2 s) along each axis,
 *   x (n . n_r)^16 (clamped at 0): a record on a surface facing elsewhere
 *     counts for nothing,
 *   x exp(-(|(x - x_r) . n_r| / (0.1 |x - x_r|))^2): a record whose
 *     offset from the point leaves its plane by more than about 6 degrees
 *     (a surface in front or behind, a bend) counts for almost nothing,
 * and only a record of the point's own material counts (a lamp a
 * centimetre below a ceiling is another surface). Those are functions of
 * the geometry only: ``irradiance_cache_interpolate`` with weights_only
 * gives the sum of each point's weights before anything is gathered, so the points whose sum is
 * below MIN_WEIGHT become records of their own.
 *
 * One work-item per point reads its 16 records in a fixed order: the same
 * bits for every work-group size and launch split.
 */

#define IC_PLANE 0.1f

/* The sum of point i's weights, and (values != 0) the weighted sum of the
 * records' irradiance into *sum. */
static float ic_gather(int i, int width, int height, int spacing, int grid_w, int grid_h,
                       __global const int *cells, __global const float4 *rec_pos, __global const float4 *rec_nrm,
                       __global const int *tri_material, float4 pos, float4 nrm, __global const float4 *values,
                       float3 *sum)
{
    int x = i % width, y = (i / width) % height;
    int gx0 = x / spacing, gy0 = y / spacing;
    int material = tri_material[as_int(pos.w)];
    float reach = 2.0f * (float)spacing;
    float total = 0.0f;
    *sum = (float3)(0.0f);
    for (int dy = -1; dy <= 2; ++dy) {
        int gy = gy0 + dy;
        if (gy < 0 || gy >= grid_h) continue;
        float wy = 1.0f - fabs((float)(gy * spacing - y)) / reach;
        if (wy <= 0.0f) continue;
        for (int dx = -1; dx <= 2; ++dx) {
            int gx = gx0 + dx;
            if (gx < 0 || gx >= grid_w) continue;
            int r = cells[gy * grid_w + gx];
            if (r < 0) continue;
            float wx = 1.0f - fabs((float)(gx * spacing - x)) / reach;
            if (wx <= 0.0f) continue;
            float4 rp = rec_pos[r];
            if (tri_material[as_int(rp.w)] != material) continue;
            float3 rn = rec_nrm[r].xyz;
            float c = fmax(dot(nrm.xyz, rn), 0.0f);
            if (c <= 0.0f) continue;
            float3 d = pos.xyz - rp.xyz;
            float t = fabs(dot(d, rn)) / (IC_PLANE * length(d) + 1e-30f);
            float c2 = c * c, c4 = c2 * c2, c8 = c4 * c4;
            float w = wy * wx * (c8 * c8) * exp(-t * t);  /* (n . n_r)^16 */
            if (w <= 0.0f) continue;
            total += w;
            if (values) *sum += w * values[r].xyz;
        }
    }
    return total;
}

/* Each point's indirect irradiance: its own record's, or the weighted mean
 * of the grid records' (0 for a point that sees nothing); with
 * weights_only, each point's sum of weights instead (in .x; ``own`` and the
 * records' irradiance unread), before anything is gathered. */
__kernel void irradiance_cache_interpolate(__global const float4 *positions, __global const float4 *normals, int n,
                                           int width, int height, int spacing, int grid_w, int grid_h,
                                           __global const int *cells, __global const float4 *rec_pos,
                                           __global const float4 *rec_nrm, __global const int *tri_material,
                                           int weights_only, __global const int *own,
                                           __global const float4 *rec_irradiance, __global float4 *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int r = weights_only ? -1 : own[i];
    float4 nrm = normals[i];
    float3 e = (float3)(0.0f);
    float total = 0.0f;
    if (r >= 0) {
        e = rec_irradiance[r].xyz;
    } else if (dot(nrm.xyz, nrm.xyz) > 0.0f) {
        float3 sum;
        total = ic_gather(i, width, height, spacing, grid_w, grid_h, cells, rec_pos, rec_nrm, tri_material,
                          positions[i], nrm, weights_only ? 0 : rec_irradiance, &sum);
        if (total > 0.0f) e = sum / total;
    }
    out[i] = weights_only ? (float4)(total, 0.0f, 0.0f, 0.0f) : (float4)(e, 0.0f);
}
