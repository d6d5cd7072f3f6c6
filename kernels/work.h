/* work.h: exact work counters (DESIGN.md section 2, "everything is measured").
 *
 * Built with -DOCLGI_COUNT_WORK=1, a kernel counts its segment-sphere tests
 * (t), segment-disc tests (u) and BVH node visits in private variables and
 * adds them to work[0..2] once at its end (64-bit atomics). Built without
 * it, every macro is empty and the counters cost nothing. Kernels take the
 * `work` buffer argument either way, so the host code is the same.
 */
#ifndef OCLGI_WORK_H
#define OCLGI_WORK_H

#ifndef OCLGI_COUNT_WORK
#define OCLGI_COUNT_WORK 0
#endif

#if OCLGI_COUNT_WORK
#define WORK_DECL ulong work_t_ = 0, work_u_ = 0, work_n_ = 0
#define WORK_T(k) (work_t_ += (ulong)(k))
#define WORK_U(k) (work_u_ += (ulong)(k))
#define WORK_NODE(k) (work_n_ += (ulong)(k))
#define WORK_FLUSH(work)                                          \
    do {                                                          \
        if (work_t_) atom_add(&(work)[0], work_t_);               \
        if (work_u_) atom_add(&(work)[1], work_u_);               \
        if (work_n_) atom_add(&(work)[2], work_n_);               \
    } while (0)
#else
#define WORK_DECL
#define WORK_T(k)
#define WORK_U(k)
#define WORK_NODE(k)
#define WORK_FLUSH(work)
#endif

#endif
