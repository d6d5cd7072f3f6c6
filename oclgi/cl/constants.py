"""Constants that host and kernels share, each defined once, here.

Every program is built with ``DEFINES`` (``oclgi/cl/programs.py``): one
``-DOCLGI_<NAME>=<value>`` per entry. The kernels keep no copy and no
default: ``kernels/constants.h`` stops a build that lacks one, so the two
sides cannot drift apart. Python modules import the values from here.

Defines that change from one program to another (``count_work``, the
Photon Map's ``knn_k``) are passed per program by their drivers instead.
Struct layouts shared with the kernels are in ``oclgi/cl/layout.py``.
"""

from __future__ import annotations

# Vector lanes of the kernels' explicit SIMD: float8 / int8 / uint8, one
# AVX2 register (256 bits). PoCL does not vectorise loops across
# work-items on a CPU, so lanes are written out: detp_plain holds 8 query
# points, the disc index and ray map tests leaves in blocks of 8 discs or
# pieces, the k-nearest search scans 8 impacts at a time, order_keys makes
# 8 keys. The vector types fix it at 8 (kernels/constants.h checks).
LANES = 8

# Stacks of the device's tree walks; the host refuses a deeper tree. The
# builder (oclgi/accel/bvh_build.py) splits on the highest differing bit of
# b-bit Morton codes, then halves runs of equal codes, so its trees have at
# most 1 + b + 31 levels for fewer than 2^31 primitives.
# The scene's BVHs (kernels/bvh.h), 30-bit codes: 62 levels at most.
BVH_STACK_SIZE = 64
# The overlap walks over the disc, piece and ball trees (kernels/box_bvh.h),
# 30-bit codes: a node pushes at most its two children, so depth + 1 entries.
BOX_BVH_STACK = 64
# The same trees collapsed into 8-wide nodes (kernels/box_wide.h,
# oclgi/accel/box_wide.py): a leaf lane holds ~(first << BOX_LEAF_BITS |
# count - 1), so a leaf has at most 2^BOX_LEAF_BITS primitives. A visit
# pops one entry and pushes up to 8 (every child met, leaves too), and a
# wide tree is no deeper than its binary one (each level goes down at least
# one binary level), so 7 entries per binary level above the leaves and 8
# for the last visit always suffice for a tree the binary walk accepts.
BOX_LEAF_BITS = 8
BOX_WIDE_STACK = 7 * (BOX_BVH_STACK - 1) + LANES
# The k-nearest search's best-first descent (kernels/point_index.cl) over a
# tree on 63-bit codes: 95 levels at most.
POINT_BVH_STACK = 96
# The binned SAH builders' bins per axis (oclgi/accel/bvh_sah.py, and the
# device one's private bin arrays in kernels/bvh_sah_device.cl).
SAH_BINS = 16

# Fixed-point sums: one photon's largest power is 2^24 units, whatever the
# photon count (kernels/oclgi_types.h has the overflow bound): resolution
# 2^-24 of a photon, and 64-bit sums with room for every photon of a run.
FIXED_BITS = 24
FIXED_ONE = float(2**FIXED_BITS)  # kernels/constants.h OCLGI_FIXED_ONE

# A direction w arrives on a surface's front side (normal n) when
# w.n < -FRONT_COS_EPS, for DETP's discs and the Photon Map's impacts alike:
# a segment grazing the plane (|w.n| within float rounding of 0) counts for
# neither side. Passed as a float literal: the kernels compare in float32.
FRONT_COS_EPS = 1e-6

# Sphere cache (kernels/detp_sphere_cache.cl): most inner spheres (private
# arrays of SC_MAX_LEVELS + 1 per work-item), and the relative slack of the
# conservative segment-sphere test, at least 100 times the rounding of
# either test (the kernel's header says why).
SC_MAX_LEVELS = 64
SC_MU = 1e-4

# Digit width of the device's LSD radix sort (kernels/ordering.cl): 256
# counters per block fit private memory, and 30-bit keys take 4 passes.
RADIX_BITS = 8

# A session's path masks (kernels/update.cl) are 128 bits: one per cell of
# the grid over the scene, then six for "leaves the grid" through each face
# (bit CELL_OUTSIDE_BIT + 2 axis + side, side 1 the high one), so grids
# have at most CELL_OUTSIDE_BIT cells.
CELL_OUTSIDE_BIT = 122

# Emitter.kind (oclgi/cl/layout.py Emitter; kernels/light.h samples each,
# oclgi/scene/lights.py writes their records).
EMITTER_TRIANGLE = 0
EMITTER_POINT = 1
EMITTER_SPOT = 2
EMITTER_SUN = 3
EMITTER_SKY = 4
EMITTER_ENVMAP = 5
EMITTER_IES = 6  # a point or spot light with an IES profile (oclgi/scene/ies.py)
# The lights that emit from one point or along one direction: their direct
# light is one shadow ray (kernels/detp_direct.cl); the others are sampled.
DELTA_KINDS = (EMITTER_POINT, EMITTER_SPOT, EMITTER_SUN, EMITTER_IES)

# Material.kind (oclgi/cl/layout.py Material; kernels/bsdf.h scatters by it,
# oclgi/scene/materials.py names the kinds) and Material.flags.
BSDF_DIFFUSE = 0
BSDF_PHONG = 1
BSDF_MIRROR = 2
BSDF_DIELECTRIC = 3
BSDF_CONDUCTOR = 4
BSDF_ROUGH_DIELECTRIC = 5
MATERIAL_TWOSIDED = 1  # both sides scatter alike (else the back is black)
MATERIAL_DELTA = 2  # scatters into single directions: no density estimation there
MATERIAL_VERTEX_COLOUR = 4  # the albedo times the mesh's vertex colours (kernels/texture.h)

# Camera rays pass through mirrors and glass and sample glossy surfaces to
# a surface with a diffuse part: at most this many surfaces along the way
# (kernels/camera.cl); a ray still on its way after them sees black.
CAMERA_MAX_DEPTH = 8

# The views image_tonemap maps radiance to display pixels with
# (kernels/view_transform.h; oclgi.params.VIEWS names them).
VIEW_SRGB = 0
VIEW_AGX = 1
VIEW_FILMIC = 2

# name -> C literal, built as -DOCLGI_<NAME upper>=<literal>. FRONT_COS_EPS
# is a float literal, SC_MU a double the kernel rounds to float (as it
# always has).
DEFINES = {
    "lanes": LANES,
    "bvh_stack_size": BVH_STACK_SIZE,
    "box_bvh_stack": BOX_BVH_STACK,
    "box_leaf_bits": BOX_LEAF_BITS,
    "box_wide_stack": BOX_WIDE_STACK,
    "point_bvh_stack": POINT_BVH_STACK,
    "sah_bins": SAH_BINS,
    "fixed_bits": FIXED_BITS,
    "front_cos_eps": f"{FRONT_COS_EPS!r}f",
    "sc_max_levels": SC_MAX_LEVELS,
    "sc_mu": repr(SC_MU),
    "radix_bits": RADIX_BITS,
    "cell_outside_bit": CELL_OUTSIDE_BIT,
    "emitter_triangle": EMITTER_TRIANGLE,
    "emitter_point": EMITTER_POINT,
    "bsdf_diffuse": BSDF_DIFFUSE,
    "bsdf_phong": BSDF_PHONG,
    "bsdf_mirror": BSDF_MIRROR,
    "bsdf_dielectric": BSDF_DIELECTRIC,
    "bsdf_conductor": BSDF_CONDUCTOR,
    "bsdf_rough_dielectric": BSDF_ROUGH_DIELECTRIC,
    "material_twosided": MATERIAL_TWOSIDED,
    "material_delta": MATERIAL_DELTA,
    "material_vertex_colour": MATERIAL_VERTEX_COLOUR,
    "camera_max_depth": CAMERA_MAX_DEPTH,
    "emitter_spot": EMITTER_SPOT,
    "emitter_sun": EMITTER_SUN,
    "emitter_sky": EMITTER_SKY,
    "emitter_envmap": EMITTER_ENVMAP,
    "emitter_ies": EMITTER_IES,
    "view_srgb": VIEW_SRGB,
    "view_agx": VIEW_AGX,
    "view_filmic": VIEW_FILMIC,
}


def build_defines(per_program: dict) -> list[tuple]:
    """DEFINES and a program's own defines, as (name, value) pairs; a program
    may not set a shared constant to a value of its own."""
    clash = sorted(DEFINES.keys() & per_program.keys())
    if clash:
        raise ValueError(f"{', '.join(clash)} are shared constants (oclgi/cl/constants.py), not per-program defines")
    return [*DEFINES.items(), *per_program.items()]
