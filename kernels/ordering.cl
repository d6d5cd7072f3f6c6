/* ordering.cl: space-filling-curve keys of points and a stable device sort.
 *
 * Entry points (one work-item each unless said):
 *   order_keys      one per OCLGI_LANES (8) points, in uint8 lanes:
 *                   quantise each point in a cube of 2^bits cells per
 *                   axis and write its Hilbert
 *                   (method 1) or Morton (method 2) key, 3*bits bits
 *                   (bits <= 10: 30-bit keys).
 *   radix_histogram one per block: digit counts of the block's contiguous
 *                   chunk of keys, digit-major (hist[digit * n_blocks + b]).
 *   radix_scan      one work-item in all: exclusive prefix sum of hist.
 *   radix_scatter   one per block: walks its chunk in order and moves each
 *                   (key, value) to the next free place of its digit, so the
 *                   pass is stable.
 * The host runs histogram / scan / scatter once per digit of RADIX_BITS
 * bits, least significant digit first (LSD radix sort). Stable passes make
 * the result the unique stable order: exactly numpy.argsort(keys,
 * kind="stable"), whatever n_blocks is. Blocks are sequential loops because
 * on a CPU device (PoCL) a few long-running work-items per core beat many
 * short ones, and serial scatter is what makes the pass stable.
 *
 * Hilbert keys follow Skilling, "Programming the Hilbert curve" (AIP Conf.
 * Proc. 707, 2004): axes -> "transposed" Hilbert index, whose bits read
 * x_{b-1} y_{b-1} z_{b-1} x_{b-2} ... z_0 give the key. Morton keys read
 * the cell coordinates' own bits in that same order. Consecutive Hilbert
 * keys are face-adjacent cells (tests/test_ordering.py checks a whole grid).
 */

#include "constants.h"

#define RADIX_BUCKETS (1 << OCLGI_RADIX_BITS)

#define ORDER_HILBERT 1
#define ORDER_MORTON 2

/* Spread the low 10 bits of every lane so bit i lands on bit 3i. */
inline uint8 spread3(uint8 v)
{
    v &= 0x3ffu;
    v = (v | (v << 16)) & 0x030000ffu;
    v = (v | (v << 8)) & 0x0300f00fu;
    v = (v | (v << 4)) & 0x030c30c3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
}

inline uint8 morton3(uint8 x, uint8 y, uint8 z)
{
    return (spread3(x) << 2) | (spread3(y) << 1) | spread3(z);
}

/* All-ones lanes where v has bit Q (vector comparisons give -1 for true). */
#define LANE_MASK(v, Q) as_uint8(((v) & (Q)) != 0u)

/* One step of Skilling's "inverse undo" for axis xi at level Q (P = Q - 1):
   where xi has bit Q, invert the low bits of x0, elsewhere exchange the low
   bits of x0 and xi. Masks instead of branches: lanes may disagree. */
#define HILBERT_UNDO(x0, xi, Q, P)               \
    do {                                         \
        uint8 set_ = LANE_MASK(xi, Q);           \
        uint8 t_ = ((x0) ^ (xi)) & (P) & ~set_;  \
        (x0) ^= ((P) & set_) ^ t_;               \
        (xi) ^= t_;                              \
    } while (0)

/* Skilling's AxestoTranspose for 3 axes of 10 bits, then interleave.
   Explicit uint8 lanes and unrolled constant loops: PoCL does not vectorise
   across work-items (DESIGN.md 6); a scalar version was 4x slower.
   Coarser curves need no other code: Skilling's order-b key of a cell is
   the top 3b bits of the order-10 key of that cell scaled by 2^(10-b)
   (tests/test_ordering.py checks whole grids at b = 4 and 5). */
inline uint8 hilbert3(uint8 x, uint8 y, uint8 z)
{
    /* Inverse undo: per level, flip or swap lower bits so that every
       sub-cube is seen in the canonical orientation. */
#pragma unroll
    for (int l = 9; l >= 1; --l) {
        uint Q = 1u << l, P = Q - 1u;
        x ^= P & LANE_MASK(x, Q); /* axis 0 against itself: invert only */
        HILBERT_UNDO(x, y, Q, P);
        HILBERT_UNDO(x, z, Q, P);
    }
    /* Gray encode. */
    y ^= x;
    z ^= y;
    uint8 t = 0u;
#pragma unroll
    for (int l = 9; l >= 1; --l)
        t ^= ((1u << l) - 1u) & LANE_MASK(z, 1u << l);
    return morton3(x ^ t, y ^ t, z ^ t);
}

/* One work-item per OCLGI_LANES points. lo: the cube's lowest corner;
   inv = 2^bits / cube side (0 for a single point); cells are clamped to
   [0, 2^bits - 1]. */
__kernel void order_keys(__global const float4 *positions, int n, float4 lo, float inv, int bits,
                         int method, __global uint *keys)
{
    int base = get_global_id(0) * OCLGI_LANES;
    if (base >= n) return;
    float px[OCLGI_LANES], py[OCLGI_LANES], pz[OCLGI_LANES];
    for (int k = 0; k < OCLGI_LANES; ++k) {
        float4 p = positions[min(base + k, n - 1)]; /* padding lanes repeat the last point */
        px[k] = p.x; py[k] = p.y; pz[k] = p.z;
    }
    int top = (1 << bits) - 1, s = 10 - bits;
    /* floor as a saturating round-down conversion: defined for any float */
    uint8 x = as_uint8(clamp(convert_int8_sat_rtn((vload8(0, px) - lo.x) * inv), 0, top)) << s;
    uint8 y = as_uint8(clamp(convert_int8_sat_rtn((vload8(0, py) - lo.y) * inv), 0, top)) << s;
    uint8 z = as_uint8(clamp(convert_int8_sat_rtn((vload8(0, pz) - lo.z) * inv), 0, top)) << s;
    uint8 key = (method == ORDER_HILBERT ? hilbert3(x, y, z) : morton3(x, y, z)) >> (uint)(3 * s);
    uint out[OCLGI_LANES];
    vstore8(key, 0, out);
    for (int k = 0; k < OCLGI_LANES && base + k < n; ++k) keys[base + k] = out[k];
}

/* Counts of the digit (key >> shift) & mask over block b's chunk. */
__kernel void radix_histogram(__global const uint *keys, int n, int shift, int chunk, int n_blocks,
                              __global int *hist)
{
    int b = get_global_id(0);
    if (b >= n_blocks) return;
    int count[RADIX_BUCKETS];
    for (int d = 0; d < RADIX_BUCKETS; ++d) count[d] = 0;
    int end = min(n, (b + 1) * chunk);
    for (int i = b * chunk; i < end; ++i)
        count[(keys[i] >> shift) & (RADIX_BUCKETS - 1)]++;
    for (int d = 0; d < RADIX_BUCKETS; ++d) hist[d * n_blocks + b] = count[d];
}

/* Exclusive prefix sum, in place; m = RADIX_BUCKETS * n_blocks is small. */
__kernel void radix_scan(__global int *hist, int m)
{
    if (get_global_id(0) != 0) return;
    int sum = 0;
    for (int i = 0; i < m; ++i) {
        int c = hist[i];
        hist[i] = sum;
        sum += c;
    }
}

/* first != 0: values are the keys' own indices (the first pass). */
__kernel void radix_scatter(__global const uint *keys_in, __global const int *vals_in, int n, int shift,
                            int chunk, int n_blocks, __global const int *offsets, int first,
                            __global uint *keys_out, __global int *vals_out)
{
    int b = get_global_id(0);
    if (b >= n_blocks) return;
    int next[RADIX_BUCKETS];
    for (int d = 0; d < RADIX_BUCKETS; ++d) next[d] = offsets[d * n_blocks + b];
    int end = min(n, (b + 1) * chunk);
    for (int i = b * chunk; i < end; ++i) {
        uint k = keys_in[i];
        int j = next[(k >> shift) & (RADIX_BUCKETS - 1)]++;
        keys_out[j] = k;
        vals_out[j] = first ? i : vals_in[i];
    }
}
