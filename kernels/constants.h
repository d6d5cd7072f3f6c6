/* constants.h: the constants host and kernels share.
 *
 * The host defines each one for every build (oclgi/cl/constants.py: the
 * values and why; oclgi/cl/programs.py passes them as -DOCLGI_<NAME>).
 * There are no defaults here: a build without them stops at the #error
 * below instead of using a copy of a value that could drift from the host's.
 */
#ifndef OCLGI_CONSTANTS_H
#define OCLGI_CONSTANTS_H

#if !defined(OCLGI_LANES) || !defined(OCLGI_BVH_STACK_SIZE) || !defined(OCLGI_BOX_BVH_STACK) ||        \
    !defined(OCLGI_BOX_LEAF_BITS) || !defined(OCLGI_BOX_WIDE_STACK) ||                                 \
    !defined(OCLGI_POINT_BVH_STACK) || !defined(OCLGI_FIXED_BITS) || !defined(OCLGI_FRONT_COS_EPS) ||  \
    !defined(OCLGI_SC_MAX_LEVELS) || !defined(OCLGI_SC_MU) || !defined(OCLGI_RADIX_BITS) ||            \
    !defined(OCLGI_CELL_OUTSIDE_BIT) || !defined(OCLGI_EMITTER_TRIANGLE) || !defined(OCLGI_EMITTER_POINT) ||   \
    !defined(OCLGI_EMITTER_SPOT) || !defined(OCLGI_EMITTER_SUN) || !defined(OCLGI_EMITTER_SKY) ||  \
    !defined(OCLGI_EMITTER_ENVMAP) || !defined(OCLGI_EMITTER_IES) || !defined(OCLGI_SAH_BINS)
#error "oclgi's shared constants are not defined: build through oclgi.cl.programs (oclgi/cl/constants.py)"
#endif

#if !defined(OCLGI_BSDF_DIFFUSE) || !defined(OCLGI_BSDF_PHONG) || !defined(OCLGI_BSDF_MIRROR) ||         \
    !defined(OCLGI_BSDF_DIELECTRIC) || !defined(OCLGI_BSDF_CONDUCTOR) ||                                \
    !defined(OCLGI_BSDF_ROUGH_DIELECTRIC) || !defined(OCLGI_MATERIAL_TWOSIDED) ||                       \
    !defined(OCLGI_MATERIAL_DELTA) || !defined(OCLGI_CAMERA_MAX_DEPTH) || !defined(OCLGI_MATERIAL_VERTEX_COLOUR)
#error "oclgi's material constants are not defined: build through oclgi.cl.programs (oclgi/cl/constants.py)"
#endif

#if !defined(OCLGI_VIEW_SRGB) || !defined(OCLGI_VIEW_AGX) || !defined(OCLGI_VIEW_FILMIC)
#error "oclgi's view constants are not defined: build through oclgi.cl.programs (oclgi/cl/constants.py)"
#endif

/* One photon's largest power in fixed-point units (segment.h). */
#define OCLGI_FIXED_ONE ((float)(1L << OCLGI_FIXED_BITS))

/* The lanes are float8, int8 and uint8 vectors. */
#if OCLGI_LANES != 8
#error "OCLGI_LANES must be 8"
#endif

#endif
