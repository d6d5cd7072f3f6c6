"""numpy dtypes of every struct shared with the kernels.

The C side is ``kernels/oclgi_types.h``; ``tests/test_layout.py`` builds
``kernels/layout_probe.cl`` and checks that sizes and field offsets agree, so
a change on one side without the other fails the tests. Structs use
``float[3]`` + a 4-byte field rather than ``float3`` (which OpenCL pads to 16
bytes) so that every layout is plain and 16-byte aligned; the device's
blocks are whole float8 / int8 (or float4) vectors, which have no padding.
"""

import numpy as np

from .constants import (  # noqa: F401  (Emitter.kind's values, kept here)
    EMITTER_POINT, EMITTER_SKY, EMITTER_SPOT, EMITTER_SUN, EMITTER_TRIANGLE, LANES)

f4, i4 = np.float32, np.int32

# BVH node, 32 bytes. Inner node: count == 0, children at first and first+1
# (siblings are adjacent). Leaf: triangles [first, first + count).
BvhNode = np.dtype([("lo", f4, 3), ("first", i4), ("hi", f4, 3), ("count", i4)])

# The scene's wide BVH node, 224 bytes (kernels/bvh.h, oclgi/accel/bvh_wide.py):
# the boxes of up to 8 children as SoA lanes, and per lane the child: an
# inner child's node index (>= 0) or a leaf's ~(first_tri << 3 | count - 1),
# which oclgi/accel/bvh_leaf_blocks.py recodes to point at its TriBlock4
# records; unused lanes have lo = hi = +inf.
WIDE = LANES  # one float8 per field
BvhNode8 = np.dtype([("lox", f4, WIDE), ("loy", f4, WIDE), ("loz", f4, WIDE), ("hix", f4, WIDE), ("hiy", f4, WIDE),
                     ("hiz", f4, WIDE), ("child", i4, WIDE)])

# A wide leaf's triangles for the 4-lane watertight test, 160 bytes
# (oclgi/accel/bvh_leaf_blocks.py writes them after the wide nodes, in the
# nodes' buffer; kernels/geometry.h tri4_intersect tests them): the
# coordinates of v0, v1, v2 of up to 4 triangles as SoA lanes, and their
# ids in scene order (-1 in unused lanes).
TriBlock4 = np.dtype([(f"v{k}{a}", f4, 4) for k in range(3) for a in "xyz"] + [("id", i4, 4)])

# Triangle in BVH order, 48 bytes: its three vertices (not edges, so that
# triangles sharing an edge see bit-identical vertices and the watertight
# test holds) and its id in scene order.
Tri = np.dtype([("v0", f4, 3), ("id", i4), ("v1", f4, 3), ("pad1", i4), ("v2", f4, 3), ("pad2", i4)])

# An object placed in the world, 144 bytes: affine transforms as 3x4 rows
# (a b c t) both ways, the world box, the root of the object's BVH and its
# triangle range (scene order).
Instance = np.dtype(
    [
        ("world_from_object", f4, (3, 4)), ("object_from_world", f4, (3, 4)),
        ("lo", f4, 3), ("root", i4), ("hi", f4, 3), ("first_tri", i4), ("n_tris", i4), ("pad", i4, 3),
    ]
)

# The world boxes of 8 consecutive instances as SoA lanes, 192 bytes
# (kernels/bvh.h scene_traverse; oclgi/scene/instance_boxes.py writes them
# after the Instance records); lanes past the last instance lo = hi = +inf.
InstanceBoxes = np.dtype([("lox", f4, LANES), ("loy", f4, LANES), ("loz", f4, LANES), ("hix", f4, LANES),
                          ("hiy", f4, LANES), ("hiz", f4, LANES)])

# One stored path segment, 48 bytes, at slot path * max_depth + bounce.
# t_end is the distance to the hit (inf when the segment leaves the scene);
# tri is the hit triangle (scene order) or -1; an empty slot is all zeros.
Segment = np.dtype(
    [("org", f4, 3), ("t_end", f4), ("dir", f4, 3), ("tri", i4), ("power", f4, 3), ("path", i4)]
)

# Material, 64 bytes (kernels/bsdf.h reads it, oclgi/scene/materials.py
# writes it): kind BSDF_*, flags MATERIAL_*; albedo is the diffuse part's
# reflectance (a dielectric's transmission tint); specular the highlight's,
# mirror's or conductor's reflectance (a dielectric's reflection tint);
# exponent the Phong lobe's n, roughness GGX's alpha, ior the dielectric's
# index (inside over outside); texture the albedo's (a Texture index), -1: none.
Material = np.dtype(
    [
        ("albedo", f4, 3), ("kind", i4),
        ("emission", f4, 3), ("flags", i4),
        ("specular", f4, 3), ("exponent", f4),
        ("roughness", f4), ("ior", f4), ("texture", i4), ("pad", i4),
    ]
)

# Texture, 16 bytes (oclgi/scene/textures.py, kernels/texture.h): a texture's
# texels are width x height float4 from offset in the scene's texel array,
# row-major, the top row first.
Texture = np.dtype([("offset", i4), ("width", i4), ("height", i4), ("pad", i4)])

# Background, 48 bytes (kernels/background.h; oclgi/scene/background.py
# writes it): what a camera ray that leaves the scene sees. kind -1: black;
# EMITTER_SKY: radiance (from above the plane normal to up when hemisphere
# is 1); EMITTER_ENVMAP: the width x height radiance texels from offset in
# the background's texel array (Mitsuba's equirectangular convention).
Background = np.dtype(
    [
        ("radiance", f4, 3), ("kind", i4),
        ("up", f4, 3), ("hemisphere", i4),
        ("offset", i4), ("width", i4), ("height", i4), ("pad", i4),
    ]
)

# Emitter, 64 bytes (kernels/oclgi_types.h has the fields of each kind,
# kernels/light.h samples them, oclgi/scene/lights.py writes them): p, e1,
# e2 the kind's points and vectors, a and b its two numbers (cone cosines,
# the bounding sphere's radius, the sky's hemisphere flag), tri the area
# light's triangle (-1 for the others). power = the largest power the kind
# gives a photon / its selection probability, in units of phi_max (<= 1).
Emitter = np.dtype(
    [
        ("p", f4, 3), ("kind", i4),
        ("e1", f4, 3), ("tri", i4),
        ("e2", f4, 3), ("a", f4),
        ("power", f4, 3), ("b", f4),
    ]
)

# The device's blocks (kernels/oclgi_types.h): leaves of the accelerated
# DETP variants, LANES primitives each, one per lane of every field.
L = LANES

# 8 discs of a disc-index leaf, 256 bytes (estimators/detp_disc_index.py):
# each disc's centre, normal and squared radius; padding lanes have a zero normal.
DiscBlock = np.dtype([("x", f4, L), ("y", f4, L), ("z", f4, L), ("nx", f4, L), ("ny", f4, L), ("nz", f4, L),
                      ("r2", f4, L), ("id", i4, L)])

# 8 segment pieces of a ray-map leaf, 320 bytes (estimators/detp_ray_map.py):
# the whole segment's o, w and t_end, its slot in the batch, and the piece's
# claim range; padding lanes have w = 0.
PieceBlock = np.dtype(
    [
        ("ox", f4, L), ("oy", f4, L), ("oz", f4, L), ("wx", f4, L), ("wy", f4, L), ("wz", f4, L),
        ("t_end", f4, L), ("slot", i4, L), ("claim_lo", f4, L), ("claim_hi", f4, L),
    ]
)

# A disc the ray map queries with, 64 bytes: centre, query point id, unit
# normal, padded box.
RayMapDisc = np.dtype(
    [("x", f4, 3), ("id", i4), ("n", f4, 3), ("pad1", i4), ("lo", f4, 3), ("pad2", i4), ("hi", f4, 3), ("pad3", i4)]
)

# A segment in a sphere-cache list, 32 bytes, made on the device
# (kernels/detp_sphere_cache.cl): (o, t_end + ext) and (w, 1 / |w|^2).
ScRecord = np.dtype([("org_tmax", f4, 4), ("dir_inv2", f4, 4)])

STRUCTS = {
    "BvhNode": BvhNode, "BvhNode8": BvhNode8, "TriBlock4": TriBlock4, "Tri": Tri,
    "Instance": Instance, "InstanceBoxes": InstanceBoxes, "Segment": Segment,
    "Material": Material, "Texture": Texture, "Background": Background, "Emitter": Emitter,
    "DiscBlock": DiscBlock, "PieceBlock": PieceBlock, "RayMapDisc": RayMapDisc, "ScRecord": ScRecord,
}

