/* prefetch.h: asking for a listed path's slots before its work-item runs.
 *
 * Kernels over a list of paths (update.cl, detp_disc_index.cl, the
 * re-trace) read a few percent of a session's store, hundreds of MB of
 * path-major slots, at strides no hardware prefetcher follows: every path
 * starts with a cache miss (perf, Sponza's listed pass: 76% of its own
 * samples on the instruction after a slot's first load). A CPU runtime
 * runs a work-group's work-items one after another on one core, so a
 * work-item that asks for the slots of the path OCLGI_PREFETCH_AHEAD items
 * ahead has them in cache by the time that work-item starts (12.2 -> 9.6
 * ms for that pass). OpenCL's prefetch() compiles to nothing on PoCL; the
 * program cache sets OCLGI_PREFETCH_AHEAD on CPU devices only (clang's
 * __builtin_prefetch), 0 elsewhere, where these are no-ops. A prefetch
 * never changes a result.
 */
#ifndef OCLGI_PREFETCH_H
#define OCLGI_PREFETCH_H

#include "oclgi_types.h"

#if OCLGI_PREFETCH_AHEAD > 0
/* the `lines` 64-byte lines from p (a slot run is 48-byte slots from a
 * 64-byte boundary when max_depth is a multiple of 4) */
#define prefetch_lines(p, lines)                                        \
    do {                                                                \
        __global const char *c_ = (__global const char *)(p);           \
        for (int l_ = 0; l_ < (lines); ++l_) __builtin_prefetch(c_ + 64 * l_, 0, 3); \
    } while (0)
#else
#define prefetch_lines(p, lines) ((void)0)
#endif

/* Work-item i of a kernel over list[0 .. n): the first `slots` slots of
 * path list[i + OCLGI_PREFETCH_AHEAD] (a path holds about three segments
 * on average; its later slots follow in lines the core fetches on its own). */
inline void prefetch_listed_path(__global const Segment *segments, __global const int *list, int i, int n,
                                 int max_depth, int slots)
{
#if OCLGI_PREFETCH_AHEAD > 0
    int j = i + OCLGI_PREFETCH_AHEAD;
    if (list && j < n) prefetch_lines(segments + (size_t)list[j] * max_depth, (slots * (int)sizeof(Segment) + 63) / 64);
#else
    (void)segments, (void)list, (void)i, (void)n, (void)max_depth, (void)slots;
#endif
}

/* Work-item k of a re-trace over paths[0 .. n), path paths[k] resuming
 * at bounce starts[k]: the slot that path paths[k + OCLGI_PREFETCH_AHEAD]
 * resumes from (the one before its start; two lines hold a 48-byte slot). */
inline void prefetch_resumed_path(__global const Segment *segments, __global const int *paths,
                                  __global const int *starts, int k, int n, int max_depth)
{
#if OCLGI_PREFETCH_AHEAD > 0
    int j = k + OCLGI_PREFETCH_AHEAD;
    if (j < n) prefetch_lines(segments + (size_t)paths[j] * max_depth + max(starts[j] - 1, 0), 2);
#else
    (void)segments, (void)paths, (void)starts, (void)k, (void)n, (void)max_depth;
#endif
}

#endif
