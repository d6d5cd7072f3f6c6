/* segment.h: the one reader (and writer) of a stored segment.
 *
 * The store holds one Segment (oclgi_types.h) per slot, path * max_depth +
 * bounce, a path's segments in bounce order. Reading a path:
 *   - a slot with a zero direction ends it (photon_trace.cl zero-fills the
 *     slots past a path's end), unless its tri is SEGMENT_HOLE: then it is a
 *     hole, a slot an update's scratch store leaves out (update.cl), and the
 *     path goes on after it;
 *   - bounce 0, the segment leaving a light, counts only with count_emitted
 *     (without it, estimates are of indirect light).
 * Every path walk starts at segment_first and steps as
 *
 *     SegmentView s;
 *     if (!segment_read(slot, &s)) {
 *         if (segment_is_hole(slot)) continue;
 *         break; (the path's end)
 *     }
 *
 * a kernel that meets slots one by one asks segment_counted. (A status code
 * out of segment_read, with the two branches on it, made detp_plain's inner
 * loop 10 to 20% longer in instructions: this shape compiles to the loop of
 * the hand-written decode it replaced.)
 *
 * A slot is read as float4s: (org, t_end) and (dir, tri), all that a test
 * needs, and the power (the third) only for a segment that counts: most
 * tested segments cross nothing. Slots are 48 bytes from a buffer's start,
 * so their float4s are aligned.
 *
 * Fixed point: every estimator quantises a power once, as
 * convert_long3_rte(power * 2^OCLGI_FIXED_BITS) (segment_quantise;
 * oclgi_types.h says why the 64-bit sums cannot overflow), so equal
 * segments give equal sums in every kernel, and -q is exact (rounding to
 * nearest even is symmetric). Powers are stored in units of the largest
 * photon power, whatever the photon count: the quantisation does not depend
 * on the run, so the sums of disjoint path ranges add up exactly.
 */
#ifndef OCLGI_SEGMENT_H
#define OCLGI_SEGMENT_H

#pragma OPENCL FP_CONTRACT OFF

#include "oclgi_types.h"

#define SEGMENT_HOLE (-2) /* tri of a hole (zero direction, the path goes on) */

typedef struct {
    float3 o;    /* origin */
    float3 w;    /* direction */
    float t_end; /* distance to the hit; INFINITY when the segment escapes */
    int tri;     /* hit triangle (scene order), -1 when none */
} SegmentView;

/* The first bounce that counts: bounce 0 leaves a light, and counts only
 * with count_emitted. */
inline int segment_first(int count_emitted)
{
    return count_emitted ? 0 : 1;
}

inline int segment_counted(int b, int count_emitted)
{
    return b >= segment_first(count_emitted);
}

/* The segment of a slot, whatever the slot holds. */
inline void segment_load(__global const Segment *slot, SegmentView *s)
{
    __global const float4 *f = (__global const float4 *)slot;
    float4 f0 = f[0], f1 = f[1];
    s->o = f0.xyz;
    s->t_end = f0.w;
    s->w = f1.xyz;
    s->tri = as_int(f1.w);
}

/* A step of a path walk: 1 with s filled when the slot holds a segment, 0
 * at a hole or at the path's end (segment_is_hole tells which). */
inline int segment_read(__global const Segment *slot, SegmentView *s)
{
    float4 d = ((__global const float4 *)slot)[1];
    if (d.x == 0.0f && d.y == 0.0f && d.z == 0.0f) return 0;
    segment_load(slot, s);
    return 1;
}

inline int segment_is_hole(__global const Segment *slot)
{
    return slot->tri == SEGMENT_HOLE;
}

/* Does the slot hold an impact (Impact Count, Photon Maps), a segment that
 * ends on a surface? Empty slots and holes have tri < 0: the tri alone
 * tells, without the path rules. */
inline int segment_impact(__global const Segment *slot)
{
    return slot->tri >= 0;
}

/* Where the segment ends: an impact's position. One expression for every
 * kernel, so that positions agree bit for bit. */
inline float3 segment_end(const SegmentView *s)
{
    return s->o + s->t_end * s->w;
}

inline float3 segment_power(__global const Segment *slot)
{
    return ((__global const float4 *)slot)[2].xyz;
}

/* The one quantisation of a power into fixed-point units (header). */
inline long3 segment_quantise(float3 power)
{
    return convert_long3_rte(power * OCLGI_FIXED_ONE);
}

inline long3 segment_fixed_power(__global const Segment *slot)
{
    return segment_quantise(segment_power(slot));
}

/* Writing: a traced segment, the empty slots past a path's end (all zeros
 * but the path id, tri -1), and a hole. */
inline void segment_write(__global Segment *slot, float3 o, float t_end, float3 w, int tri, float3 power,
                          int path)
{
    vstore3(o, 0, slot->org);
    slot->t_end = t_end;
    vstore3(w, 0, slot->dir);
    slot->tri = tri;
    vstore3(power, 0, slot->power);
    slot->path = path;
}

inline void segment_write_empty(__global Segment *slot, int path)
{
    segment_write(slot, (float3)(0.0f), 0.0f, (float3)(0.0f), -1, (float3)(0.0f), path);
}

inline Segment segment_hole(int path)
{
    return (Segment){{0.0f, 0.0f, 0.0f}, 0.0f, {0.0f, 0.0f, 0.0f}, SEGMENT_HOLE, {0.0f, 0.0f, 0.0f}, path};
}

#endif
