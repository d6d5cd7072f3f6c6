/* oclgi_types.h: structs shared with the host (and, through constants.h,
 * the constants the host defines for every build).
 *
 * Mirrors oclgi/cl/layout.py field for field; tests/test_layout.py checks
 * sizes and offsets through layout_probe.cl. No float3 in these structs
 * (OpenCL pads it to 16 bytes): float[3] + a 4-byte field, read with vload3;
 * the device's blocks (at the end) are whole vectors.
 *
 * Fixed-point sums (DESIGN.md section 2): a photon carries its power in
 * units of phi_max, the largest power an emitter gives one photon path (the
 * host divides the emitters' records by it, oclgi/scene/compiled.py), and
 * every contribution is quantised once as convert_long_rte(power *
 * 2^OCLGI_FIXED_BITS) (segment_quantise, segment.h; OCLGI_FIXED_BITS = 24),
 * then added with 64-bit integer atomics, so sums are order-independent.
 * Neither depends on the photon count: 1/n is applied only when sums are
 * resolved into watts (the resolve kernels' factor), so the sums of
 * disjoint path ranges (batches, resumed runs, MPI ranks) add up exactly.
 * Russian roulette survives with the largest component of the bounce's
 * sample weight f cos / pdf, which every kind keeps at most 1 (bsdf.h,
 * oclgi/scene/materials.py), so no segment carries more than phi_max: one contribution is at most 2^24, and a sum over n_paths *
 * max_depth contributions stays below 2^(24 + 30 + 8) = 2^62 < 2^63 for
 * 10^9 photons and max_depth <= 256 (the host enforces both limits, for
 * the whole of a run however it is split or extended). Resolution: 2^-24
 * of a photon's power.
 */
#ifndef OCLGI_TYPES_H
#define OCLGI_TYPES_H

#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable

#include "constants.h"

#define OCLGI_PI 3.14159265358979323846f

typedef struct {
    float lo[3];
    int first;   /* inner: left child (right = first + 1); leaf: first triangle */
    float hi[3];
    int count;   /* 0 for inner nodes */
} BvhNode;

/* The scene's wide node (bvh.h): up to 8 children, their boxes as SoA
 * float8 fields (child k in lane k), so one float8 op slabs every child
 * against one plane. child[k] >= 0: an inner child, index of its BvhNode8;
 * child[k] < 0: a leaf of count 1..8 triangles, ~(offset / 32 << 3 |
 * (count - 1)), its triangles in TriBlock4 records from that byte offset
 * in the nodes' buffer (oclgi/accel/bvh_leaf_blocks.py recodes the
 * collapse's ~(first_tri << 3 | (count - 1)), a run of the Tri array).
 * An unused lane has the box lo = hi = +inf, which every ray misses (bvh.h
 * says why). 224 bytes, 32-byte aligned. */
typedef struct {
    float8 lox;
    float8 loy;
    float8 loz;
    float8 hix;
    float8 hiy;
    float8 hiz;
    int8 child;
} BvhNode8;

/* Up to 4 triangles of a wide leaf as SoA lanes (geometry.h
 * tri4_intersect), stored after the wide nodes in the same buffer (bvh.h):
 * vertex coordinates, then ids in scene order (-1: unused lane). 160 bytes. */
typedef struct {
    float4 v0x;
    float4 v0y;
    float4 v0z;
    float4 v1x;
    float4 v1y;
    float4 v1z;
    float4 v2x;
    float4 v2y;
    float4 v2z;
    int4 id;
} TriBlock4;

typedef struct {
    float v0[3];
    int id;      /* triangle id in scene order */
    float v1[3]; /* vertices, not edges: shared vertices stay bit-identical */
    int pad1;
    float v2[3];
    int pad2;
} Tri;

/* A stored segment; segment.h reads and writes them (ends of paths, holes). */
typedef struct {
    float org[3];
    float t_end; /* distance to the hit; INFINITY when the segment escapes */
    float dir[3];
    int tri;     /* hit triangle (scene order), -1 when none */
    float power[3];
    int path;    /* global path id */
} Segment;

/* One object placed in the world (the top level of the scene's BVH). */
typedef struct {
    float world_from_object[12]; /* rows (a b c t): p_world = A p_object + t */
    float object_from_world[12]; /* its inverse */
    float lo[3];                 /* world-space box of the moved object */
    int root;                    /* root node of the object's BVH */
    float hi[3];
    int first_tri;               /* the object's triangles: [first_tri, first_tri + n_tris) */
    int n_tris;
    int pad[3];
} Instance;

/* The world boxes of 8 consecutive instances as SoA lanes (instance 8 g + k
 * in lane k of group g), stored after the Instance records in the same
 * buffer, from the next 32-byte boundary (oclgi/scene/instance_boxes.py
 * writes them): one float8 slab
 * test culls 8 instances (bvh.h scene_traverse). Lanes past the last
 * instance have lo = hi = +inf. 192 bytes, 32-byte aligned. */
typedef struct {
    float8 lox;
    float8 loy;
    float8 loz;
    float8 hix;
    float8 hiy;
    float8 hiz;
} InstanceBoxes;

/* A material (bsdf.h scatters by it; oclgi/scene/materials.py writes it). */
typedef struct {
    float albedo[3];   /* the diffuse part's reflectance; a dielectric's transmission tint */
    int kind;          /* OCLGI_BSDF_* */
    float emission[3]; /* radiance, emitted on the normal's side */
    int flags;         /* OCLGI_MATERIAL_TWOSIDED | OCLGI_MATERIAL_DELTA */
    float specular[3]; /* highlight / mirror / conductor reflectance; a dielectric's reflection tint */
    float exponent;    /* modified Phong's n */
    float roughness;   /* GGX alpha */
    float ior;         /* a dielectric's index, inside over outside */
    int texture;       /* the albedo's texture (Texture index), -1: none */
    int pad;
} Material;

/* A texture: width x height float4 texels from offset (texture.h). */
typedef struct {
    int offset;
    int width;
    int height;
    int pad;
} Texture;

/* What a camera ray leaving the scene sees (background.h). */
typedef struct {
    float radiance[3]; /* a uniform sky's */
    int kind;          /* -1: black; OCLGI_EMITTER_SKY or OCLGI_EMITTER_ENVMAP */
    float up[3];
    int hemisphere;    /* 1: the sky is above the plane normal to up only */
    int offset;        /* an environment map's texels */
    int width;
    int height;
    int pad;
} Background;

/* One light (kernels/light.h samples it; oclgi/scene/lights.py writes
 * it). Fields by kind:
 *             p            e1            e2       a           b
 *   TRIANGLE  v0           v1 - v0       v2 - v0  0           0
 *   POINT     position     0             0        0           0
 *   SPOT      position     unit axis     0        cos(cone)   cos(falloff start)
 *   SUN       sphere c     unit travel   0        sphere R    0
 *   SKY       sphere c     unit up       0        sphere R    1: upper hemisphere, 0: sphere
 *   ENVMAP    sphere c     0             (W,H,0)  sphere R    0
 *   IES       position     unit nadir    unit C0  cos(cone)   cos(falloff start) (-1, -1: no cone)
 * (c, R: the scene's bounding sphere, which the sun's and sky's discs lie
 * outside.) tri: the triangle's id (scene order); an ENVMAP's or IES's
 * tables' offset in the emitter CDF buffer (light.h); -1 for the other kinds.
 * power: the largest power the kind gives a photon / its selection
 * probability, in units of phi_max, so never above 1. */
typedef struct {
    float p[3];
    int kind;       /* OCLGI_EMITTER_* (constants.h) */
    float e1[3];
    int tri;
    float e2[3];
    float a;
    float power[3];
    float b;
} Emitter;

/* The device's blocks: the accelerated DETP variants' leaves, tested
 * OCLGI_LANES (8) primitives at a time, one per lane of each float8 field
 * (PoCL does not vectorise across work-items: explicit lanes). */

/* 8 discs of a disc-index leaf (detp_disc_index.h); padding lanes have a
 * zero normal, which never passes DETP_TEST (w.n = 0). */
typedef struct {
    float8 x;
    float8 y;
    float8 z;
    float8 nx;
    float8 ny;
    float8 nz;
    float8 r2; /* squared radius of each disc (per point: adaptive radii) */
    int8 id;   /* query point */
} DiscBlock;

/* 8 segment pieces of a ray-map leaf (detp_ray_map.cl); padding lanes have
 * w = 0, which never passes DETP_TEST. */
typedef struct {
    float8 ox;
    float8 oy;
    float8 oz;
    float8 wx;
    float8 wy;
    float8 wz;
    float8 t_end; /* of the whole segment */
    int8 slot;    /* the segment's slot in its batch (for its power) */
    float8 claim_lo;
    float8 claim_hi;
} PieceBlock;

/* A disc the ray map queries with (detp_ray_map.cl): centre, normal and
 * padded box. */
typedef struct {
    float x[3];
    int id; /* query point */
    float n[3];
    int pad1;
    float lo[3];
    int pad2;
    float hi[3];
    int pad3;
} RayMapDisc;

/* A segment in a sphere-cache list (detp_sphere_cache.cl): (o, tmax) and
 * (w, 1 / |w|^2) as whole float4s; its slot lies in a parallel int array. */
typedef struct {
    float4 org_tmax;
    float4 dir_inv2;
} ScRecord;

#endif
