/* bvh_sah_device.cl: one level of the binned SAH BVH build on the device
 * (the host loop and the tree layout: oclgi/accel/bvh_sah_device.py).
 *
 * Entry point (one work-item per node of the level):
 *   sah_split  the node's range [start, start + size) of `src`: centroid
 *              bounds, the primitives' bins on each axis (private boxes
 *              and counts), the cheapest split, and the stable partition
 *              of the range into `dst` (left primitives first, each side
 *              in its old order). A child that is a leaf (at most
 *              leaf_size primitives) also writes its primitive ids to
 *              `order`, their final place. out[node] = the left child's
 *              size, or -1 where no bin boundary separates the centroids
 *              (the host halves those nodes, as bvh_sah.py does).
 *              children[4 node ..]: the left child's box and centroid
 *              bounds, then the right child's (float8: lo, hi): the boxes
 *              of the next level's nodes, and the centroid bounds its
 *              sah_split starts from (bounds[], lo > hi where unknown).
 *
 * The arithmetic is bvh_sah.py's, operation for operation, so that the
 * device tree equals the numpy builder's bit for bit: centroids
 * float32(0.5 * (double(lo) + double(hi))); the bin scale n_bins / extent
 * correctly rounded to float (computed in double: double rounding is
 * innocuous for a quotient of floats); bins (int)((c - cmin) * scale) in
 * float; box areas e0*e1 + e1*e2 + e2*e0 in float, left to right; costs
 * n_left * area_left + n_right * area_right in double (numpy's int64 times
 * float32); the best cost so far kept as a float (numpy stores it in a
 * float32 array) and beaten strictly, the first bin and the lowest axis
 * winning ties. FP contraction is off (a fused multiply-add would round
 * once where numpy rounds twice); every rounding step is its own statement.
 * Work-items share nothing, so the result does not depend on the
 * work-group size or the order work-items run in.
 *
 * A row is two float4: lo.xyz with the primitive id's bits in w, hi.xyz.
 */

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#include "constants.h"

#define BINS OCLGI_SAH_BINS

static inline float4 centroid(float4 lo, float4 hi) {
    return convert_float4(0.5 * (convert_double4(lo) + convert_double4(hi)));
}

/* Half the surface area of a box, 0 for an empty one (lo > hi). */
static inline float half_area(float4 lo, float4 hi) {
    float4 e = hi - lo;
    e = select(e, (float4)(0.0f), e < 0.0f);  /* numpy's maximum(e, 0): -inf -> 0 */
    float a = e.x * e.y;
    float b = e.y * e.z;
    float c = e.z * e.x;
    float s = a + b;
    return s + c;
}

kernel void sah_split(global const float8 *src, global float8 *dst, global int *order, global const int2 *nodes,
                      global const float8 *bounds, int n_nodes, int n_bins, int leaf_size, global int *out,
                      global float8 *children) {
    int node = get_global_id(0);
    if (node >= n_nodes) return;
    int start = nodes[node].x, size = nodes[node].y, end = start + size;

    /* the centroid bounds, as the parent's partition found them (unknown,
     * lo > hi, at the root and below host-halved nodes: found here) */
    float4 cmin = bounds[node].lo, cmax = bounds[node].hi;
    if (cmin.x > cmax.x) {
        for (int j = start; j < end; j++) {
            float8 r = src[j];
            float4 c = centroid(r.lo, r.hi);
            cmin = min(cmin, c);
            cmax = max(cmax, c);
        }
    }
    float4 ext = cmax - cmin;
    float4 scale;
    for (int k = 0; k < 3; k++)
        scale[k] = ext[k] > 0.0f ? (float)((double)n_bins / (double)ext[k]) : 0.0f;
    scale.w = 0.0f;
    int4 top = (int4)(n_bins - 1);

    float4 blo[3 * BINS], bhi[3 * BINS];
    int cnt[3 * BINS];
    for (int i = 0; i < 3 * n_bins; i++) {
        blo[i] = (float4)(INFINITY);
        bhi[i] = (float4)(-INFINITY);
        cnt[i] = 0;
    }
    for (int j = start; j < end; j++) {
        float8 r = src[j];
        float4 lo = (float4)(r.s012, 0.0f), hi = (float4)(r.s456, 0.0f);
        float4 d = centroid(r.lo, r.hi) - cmin;
        int4 b = min(convert_int4_rtz(d * scale), top);
        for (int k = 0; k < 3; k++) {
            int i = k * n_bins + b[k];
            blo[i] = min(blo[i], lo);
            bhi[i] = max(bhi[i], hi);
            cnt[i]++;
        }
    }

    float best_cost = INFINITY;
    int best_axis = 0, best_bin = 0;
    for (int k = 0; k < 3; k++) {
        int base = k * n_bins;
        /* right side of cut b: bins b+1 .. n_bins-1 */
        float r_area[BINS];
        int r_count[BINS];
        float4 lo = (float4)(INFINITY), hi = (float4)(-INFINITY);
        int n = 0;
        for (int b = n_bins - 1; b > 0; b--) {
            lo = min(lo, blo[base + b]);
            hi = max(hi, bhi[base + b]);
            n += cnt[base + b];
            r_area[b - 1] = half_area(lo, hi);
            r_count[b - 1] = n;
        }
        lo = (float4)(INFINITY);
        hi = (float4)(-INFINITY);
        n = 0;
        double axis_cost = INFINITY;
        int axis_bin = 0;
        for (int b = 0; b < n_bins - 1; b++) {
            lo = min(lo, blo[base + b]);
            hi = max(hi, bhi[base + b]);
            n += cnt[base + b];
            double left = (double)n * (double)half_area(lo, hi);
            double right = (double)r_count[b] * (double)r_area[b];
            double cost = left + right;
            if (n == 0 || r_count[b] == 0) cost = INFINITY;
            if (cost < axis_cost) {
                axis_cost = cost;
                axis_bin = b;
            }
        }
        if (axis_cost < (double)best_cost) {
            best_cost = (float)axis_cost;
            best_axis = k;
            best_bin = axis_bin;
        }
    }
    if (!isfinite(best_cost)) {
        out[node] = -1;
        return;
    }

    /* the children's boxes: the unions of their bins */
    int n_left = 0;
    float4 llo = (float4)(INFINITY), lhi = (float4)(-INFINITY), rlo = llo, rhi = lhi;
    for (int b = 0; b < n_bins; b++) {
        int i = best_axis * n_bins + b;
        if (b <= best_bin) {
            n_left += cnt[i];
            llo = min(llo, blo[i]);
            lhi = max(lhi, bhi[i]);
        } else {
            rlo = min(rlo, blo[i]);
            rhi = max(rhi, bhi[i]);
        }
    }
    bool leaf_l = n_left <= leaf_size, leaf_r = size - n_left <= leaf_size;
    float c_min = cmin[best_axis], c_scale = scale[best_axis];
    float4 lcmin = (float4)(INFINITY), lcmax = (float4)(-INFINITY), rcmin = lcmin, rcmax = lcmax;
    int l = start, r = start + n_left;
    for (int j = start; j < end; j++) {
        float8 row = src[j];
        float4 c = centroid(row.lo, row.hi);
        float d = c[best_axis] - c_min;
        int b = min(convert_int_rtz(d * c_scale), n_bins - 1);
        bool left = b <= best_bin;
        int at = left ? l++ : r++;
        dst[at] = row;
        if (left ? leaf_l : leaf_r) order[at] = as_int(row.s3);
        /* the children's centroid bounds, for their own level */
        if (left) {
            lcmin = min(lcmin, c);
            lcmax = max(lcmax, c);
        } else {
            rcmin = min(rcmin, c);
            rcmax = max(rcmax, c);
        }
    }
    out[node] = n_left;
    /* per child (left, right): box (lo, hi), then centroid bounds (lo, hi) */
    children[4 * node + 0] = (float8)(llo, lhi);
    children[4 * node + 1] = (float8)(lcmin, lcmax);
    children[4 * node + 2] = (float8)(rlo, rhi);
    children[4 * node + 3] = (float8)(rcmin, rcmax);
}
