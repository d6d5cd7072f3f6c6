/* update.cl: finding and gathering the paths a move changes (DESIGN.md 4).
 *
 * update_path_cells  one work-item per listed path: a 128-bit mask of the
 *     cells of a grid over the scene (at most 122 cells, about cubic: 5 x 5
 *     x 4 for the Cornell box, 7 x 4 x 4 for Sponza) that the path's segments
 *     meet (each segment against each padded cell its box can reach, the
 *     same slab test as below), and, from bit OCLGI_CELL_OUTSIDE_BIT (122),
 *     one bit per face of the grid a segment leaves it through.
 *     A move need only look at the paths whose mask meets the cells of the
 *     object's old and new boxes (and of the dynamic points' discs), plus
 *     the bit of each face a box reaches past: a segment meeting a box
 *     meets it inside some cell, which is in both masks, or outside the
 *     grid, past a face which both reach past. The host keeps the masks current: all
 *     paths after the trace, re-traced paths after each update.
 * update_candidates  one work-item per `chunk` paths: lists those whose
 *     mask meets the region's.
 * update_first_affected  one work-item per listed path (first[i] for list[i]):
 *     the first bounce b whose segment hit the moved object before the move (its triangle is
 *     in the object's range) or meets the object at its new pose before its
 *     own end (the object's box first, then its BVH, any hit, with the same
 *     traversal code and transform as a full trace uses, so the answer
 *     agrees with a re-trace exactly); -1 when the path is untouched. The
 *     segments before b are the same in the moved scene, so re-tracing from
 *     b gives the recomputed path.
 *     Given a BVH over discs (disc_nodes not NULL; detp_disc_index.h), it
 *     also walks every segment of the path through it: a camera session's
 *     dynamic points get their sums over the store before the update in
 *     the same pass; the update's subtract and add passes then bring them
 *     to the new store exactly (integer sums), so the store is read once
 *     per move instead of twice.
 * update_suffix_lengths  one work-item per listed path: the stored
 *     segments from its first affected bounce on (a move's statistics,
 *     read back while the device works on).
 * update_gather  one work-item per listed path: copies its slots from its
 *     first affected bounce on, with the power times sign (-1 takes a
 *     contribution away: round-to-nearest-even is symmetric, so the
 *     fixed-point sums lose exactly what they gained), into a path-major
 *     scratch store that every estimator accumulates like a batch. Slots
 *     before b become holes (segment.h): skipped, not ends.
 */
#include "bvh.h"
#include "segment.h"
#include "detp_disc_index.h"
#include "work.h"
#include "prefetch.h"
#include "lane_bits.h"

/* Does segment (o, d, t_end, tri) of a path touch object `in` (triangles
 * lo..hi) at its old pose (it ended there) or at its new one (it meets it)? */
inline int update_touches(__global const BvhNode *nodes, __global const Tri *tris, __global const Instance *in,
                          int lo, int hi, float3 o, float3 d, float t_end, int tri)
{
    if (tri >= lo && tri < hi) return 1;
    if (box_entry(in->lo, in->hi, o, 1.0f / d, t_end) == INFINITY) return 0;
    Hit h;
    h.tri = -1;
    h.t = t_end;
    return bvh_traverse(nodes, tris, in->root, xform_point(in->object_from_world, o),
                        xform_vector(in->object_from_world, d), 1, &h) >= 0;
}

/* The faces of the (convex, shrunk) grid [g0, g1] past which the segment
 * o + t d, 0 <= t <= t_end (box [lo, hi], inv = 1 / d), has points: bit 2
 * axis + side (side 1: the high face). A segment that passes through the
 * grid has its points outside after it leaves, all past the face it
 * leaves by (a line crosses a plane once), and before it enters, all past
 * the face it enters by; the faces whose crossing is within 1e-5 of the
 * leaving (entering) one are taken too, far above float rounding. Any
 * other segment: every face its box reaches past. So a box out of the
 * grid below the floor lists the paths that leave downwards, not every
 * path that leaves the grid (by an open front or roof). */
inline uint cell_faces(float3 o, float3 inv, float t_end, float3 lo, float3 hi, float3 g0, float3 g1)
{
    int3 below = lo < g0, above = hi > g1;
    uint faces = (below.x & 1) | (above.x & 2) | (below.y & 4) | (above.y & 8) | (below.z & 16) | (above.z & 32);
    if (!faces) return 0;
    float3 t0 = (g0 - o) * inv, t1 = (g1 - o) * inv;
    float3 tin = fmin(t0, t1), tout = fmax(t0, t1);
    float t_in = fmax(fmax(tin.x, tin.y), tin.z), t_out = fmin(fmin(tout.x, tout.y), tout.z);
    if (!(t_in <= t_out && t_out >= 0.0f && t_in <= t_end)) return faces; /* does not pass through */
    uint crossed = 0;
    int3 up = inv > 0.0f; /* the side a segment leaves by; it enters by the other */
    if (t_out <= t_end + t_end * 1e-5f) { /* it leaves */
        int3 by = tout <= t_out + fabs(t_out) * 1e-5f;
        crossed |= ((by.x & 1) << (up.x & 1)) | ((by.y & 1) << (2 + (up.y & 1))) | ((by.z & 1) << (4 + (up.z & 1)));
    }
    if (any(o < g0) || any(o > g1)) { /* it starts outside: it enters */
        int3 by = tin >= t_in - fabs(t_in) * 1e-5f;
        crossed |= ((by.x & 1) << (1 - (up.x & 1))) | ((by.y & 1) << (3 - (up.y & 1))) |
                   ((by.z & 1) << (5 - (up.z & 1)));
    }
    return crossed;
}

__kernel void update_path_cells(__global const Segment *segments, __global const int *path_len, int max_depth,
                                __global const int *list, int n_list, float4 grid_lo, float4 cell, int4 dims,
                                float pad, __global ulong2 *cells)
{
    int i = get_global_id(0);
    if (i >= n_list) return;
    int p = list[i];
    prefetch_listed_path(segments, list, i, n_list, max_depth, 3);
    ulong m[2] = {0, 0};
    int3 top = dims.xyz - 1;
    float3 g0 = grid_lo.xyz + pad, g1 = grid_lo.xyz + convert_float3(dims.xyz) * cell.xyz - pad; /* shrunk */
    for (int b = 0; b < path_len[p]; ++b) {
        SegmentView s;
        segment_load(&segments[(size_t)p * max_depth + b], &s);
        float3 o = s.o, d = s.w;
        float t_end = s.t_end;
        /* the cells the segment's box reaches (all, for an escaping one,
         * whose box reaches infinity along its direction) */
        int3 c0 = (int3)(0), c1 = top;
        float3 lo = select(o, (float3)(-INFINITY), d < 0.0f), hi = select(o, (float3)(INFINITY), d > 0.0f);
        if (t_end != INFINITY) {
            float3 e = segment_end(&s);
            lo = fmin(o, e);
            hi = fmax(o, e);
            c0 = clamp(convert_int3_rtn((lo - pad - grid_lo.xyz) / cell.xyz), (int3)(0), top);
            c1 = clamp(convert_int3_rtn((hi + pad - grid_lo.xyz) / cell.xyz), (int3)(0), top);
        }
        float3 inv = 1.0f / d;
        m[1] |= (ulong)cell_faces(o, inv, t_end, lo, hi, g0, g1) << (OCLGI_CELL_OUTSIDE_BIT - 64);
        /* box_slab (box.h) on each padded cell, its per-axis parts made once
         * per column, row and layer: a cell's slab times are its x column's,
         * y row's and z layer's, the same operations on the same values, and
         * fmin / fmax are exact, so a cell is marked exactly when box_slab
         * on its box says so. Columns go 8 at a time in float8 lanes (the
         * same operations in each lane), a row's cells met as a bit mask:
         * Sponza's 7 columns in one test per row. */
        for (int xb = c0.x; xb <= c1.x; xb += OCLGI_LANES) {
            int8 x = xb + (int8)(0, 1, 2, 3, 4, 5, 6, 7);
            float8 lox = grid_lo.x + convert_float8(x) * cell.x - pad;
            float8 t0x = (lox - o.x) * inv.x, t1x = (lox + cell.x + 2.0f * pad - o.x) * inv.x;
            float8 tnx = fmin(t0x, t1x), tfx = fmax(t0x, t1x);
            int8 in_range = x <= c1.x;
            for (int z = c0.z; z <= c1.z; ++z) {
                float loz = grid_lo.z + (float)z * cell.z - pad;
                float t0z = (loz - o.z) * inv.z, t1z = (loz + cell.z + 2.0f * pad - o.z) * inv.z;
                float nz = fmax(fmin(t0z, t1z), 0.0f), fz = fmin(fmax(t0z, t1z), t_end);
                for (int y = c0.y; y <= c1.y; ++y) {
                    float loy = grid_lo.y + (float)y * cell.y - pad;
                    float t0y = (loy - o.y) * inv.y, t1y = (loy + cell.y + 2.0f * pad - o.y) * inv.y;
                    float ny = fmax(fmin(t0y, t1y), nz), fy = fmin(fmax(t0y, t1y), fz);
                    ulong met = lane_bits8((fmax(tnx, ny) <= fmin(tfx, fy) * 1.0000004f) & in_range);
                    if (!met) continue;
                    int c = xb + dims.x * (y + dims.y * z); /* cell of lane 0 */
                    /* the lanes' bits at cells c .. c + 7 of the 128-bit mask */
                    if (c < 64) {
                        m[0] |= met << c;
                        if (c > 56) m[1] |= met >> (64 - c);
                    } else {
                        m[1] |= met << (c - 64);
                    }
                }
            }
        }
    }
    cells[p] = (ulong2)(m[0], m[1]);
}

/* The paths whose mask meets `region`, appended to `list` in any order (the
 * host sorts the affected ones): only a few percent of the store is read again. A
 * work-item counts its chunk's, takes their places with one atomic, then
 * writes them: an atomic per listed path, on one counter both cores
 * share, cost about a sixth of the scan (Sponza, 336,032 paths, 52,871
 * listed: 1.31 -> 1.10 ms). */
__kernel void update_candidates(__global const ulong2 *cells, int n_paths, int chunk, ulong2 region,
                                volatile __global int *count, __global int *list)
{
    int p0 = get_global_id(0) * chunk;
    if (p0 >= n_paths) return;
    int p1 = min(p0 + chunk, n_paths), k = 0;
    for (int p = p0; p < p1; ++p) {
        ulong2 m = cells[p] & region;
        k += (m.x | m.y) != 0;
    }
    if (k == 0) return;
    int at = atomic_add(count, k);
    for (int p = p0; p < p1; ++p) {
        ulong2 m = cells[p] & region;
        if (m.x | m.y) list[at++] = p;
    }
}

__kernel void update_first_affected(SCENE_ARGS, int obj, __global const Segment *segments, __global const int *list,
                                    int n_list, int max_depth, __global int *first,
                                    __global const DiscNode *disc_nodes, __global const DiscBlock *discs,
                                    int count_emitted, float ext,
                                    __global long *acc, __global ulong *work)
{
    int i = get_global_id(0);
    if (i >= n_list) return;
    int p = list[i];
    prefetch_listed_path(segments, list, i, n_list, max_depth, 3);
    __global const Instance *in = &instances[obj];
    int lo = in->first_tri, hi = in->first_tri + in->n_tris;
    int found = -1;
    WORK_DECL;
    uint visited = 0;
    ulong tests = 0;
    __global const Segment *path = segments + (size_t)p * max_depth;
    for (int b = 0; b < max_depth; ++b) {
        /* Every bounce may be the first affected one: all are read
         * (count_emitted only selects what the disc sums count). */
        SegmentView s;
        if (!segment_read(path + b, &s)) {
            if (segment_is_hole(path + b)) continue;
            break; /* the path's end */
        }
        if (found < 0 && update_touches(nodes, tris, in, lo, hi, s.o, s.w, s.t_end, s.tri))
            found = b;
        if (!disc_nodes) { /* no dynamic points: the first affected bounce is all we need */
            if (found >= 0) break;
            continue;
        }
        if (segment_counted(b, count_emitted))
            disc_index_segment(disc_nodes, discs, path + b, &s, ext, acc, &visited, &tests);
    }
    first[i] = found;
    WORK_U(tests);
    WORK_NODE(visited);
    WORK_FLUSH(work);
}

__kernel void update_gather(__global const Segment *segments, int max_depth,
                            __global const int *paths, __global const int *starts, int n_list,
                            float sign, __global Segment *out)
{
    int k = get_global_id(0);
    if (k >= n_list) return;
    prefetch_listed_path(segments, paths, k, n_list, max_depth, max_depth);
    __global const Segment *src = &segments[(size_t)paths[k] * max_depth];
    __global Segment *dst = &out[(size_t)k * max_depth];
    int b0 = starts[k];
    for (int b = 0; b < max_depth; ++b) {
        Segment s = src[b];
        if (b < b0) {
            s = segment_hole(s.path);
        } else {
            s.power[0] *= sign;
            s.power[1] *= sign;
            s.power[2] *= sign;
        }
        dst[b] = s;
    }
}

__kernel void update_suffix_lengths(__global const int *path_len, __global const int *paths,
                                    __global const int *starts, int n_list, __global int *out)
{
    int k = get_global_id(0);
    if (k >= n_list) return;
    out[k] = path_len[paths[k]] - starts[k];
}
