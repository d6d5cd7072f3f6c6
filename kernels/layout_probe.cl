/* layout_probe.cl: reports sizeof and offsetof of every shared struct, in
 * the order of oclgi/cl/layout.py (struct by struct, size first, then each
 * field), so tests/test_layout.py can compare them with the numpy dtypes;
 * after the end marker, the alignment of BvhNode8 and InstanceBoxes.
 * Entry point: layout_probe, one work-item. */
#include "oclgi_types.h"

#define SIZE(T) out[i++] = (int)sizeof(T)
/* OpenCL C has no offsetof: measure the field address in a private object. */
#define OFF(T, f) do { T t_; out[i++] = (int)((char *)&t_.f - (char *)&t_); } while (0)

__kernel void layout_probe(__global int *out)
{
    int i = 0;
    SIZE(BvhNode); OFF(BvhNode, lo); OFF(BvhNode, first); OFF(BvhNode, hi); OFF(BvhNode, count);
    SIZE(BvhNode8); OFF(BvhNode8, lox); OFF(BvhNode8, loy); OFF(BvhNode8, loz); OFF(BvhNode8, hix);
    OFF(BvhNode8, hiy); OFF(BvhNode8, hiz); OFF(BvhNode8, child);
    SIZE(TriBlock4); OFF(TriBlock4, v0x); OFF(TriBlock4, v0y); OFF(TriBlock4, v0z); OFF(TriBlock4, v1x);
    OFF(TriBlock4, v1y); OFF(TriBlock4, v1z); OFF(TriBlock4, v2x); OFF(TriBlock4, v2y); OFF(TriBlock4, v2z);
    OFF(TriBlock4, id);
    SIZE(Tri); OFF(Tri, v0); OFF(Tri, id); OFF(Tri, v1); OFF(Tri, pad1); OFF(Tri, v2); OFF(Tri, pad2);
    SIZE(Instance); OFF(Instance, world_from_object); OFF(Instance, object_from_world); OFF(Instance, lo);
    OFF(Instance, root); OFF(Instance, hi); OFF(Instance, first_tri); OFF(Instance, n_tris); OFF(Instance, pad);
    SIZE(InstanceBoxes); OFF(InstanceBoxes, lox); OFF(InstanceBoxes, loy); OFF(InstanceBoxes, loz);
    OFF(InstanceBoxes, hix); OFF(InstanceBoxes, hiy); OFF(InstanceBoxes, hiz);
    SIZE(Segment); OFF(Segment, org); OFF(Segment, t_end); OFF(Segment, dir); OFF(Segment, tri);
    OFF(Segment, power); OFF(Segment, path);
    SIZE(Material); OFF(Material, albedo); OFF(Material, kind); OFF(Material, emission); OFF(Material, flags);
    OFF(Material, specular); OFF(Material, exponent); OFF(Material, roughness); OFF(Material, ior);
    OFF(Material, texture); OFF(Material, pad);
    SIZE(Texture); OFF(Texture, offset); OFF(Texture, width); OFF(Texture, height); OFF(Texture, pad);
    SIZE(Background); OFF(Background, radiance); OFF(Background, kind); OFF(Background, up);
    OFF(Background, hemisphere); OFF(Background, offset); OFF(Background, width); OFF(Background, height);
    OFF(Background, pad);
    SIZE(Emitter); OFF(Emitter, p); OFF(Emitter, kind); OFF(Emitter, e1); OFF(Emitter, tri);
    OFF(Emitter, e2); OFF(Emitter, a); OFF(Emitter, power); OFF(Emitter, b);
    SIZE(DiscBlock); OFF(DiscBlock, x); OFF(DiscBlock, y); OFF(DiscBlock, z); OFF(DiscBlock, nx);
    OFF(DiscBlock, ny); OFF(DiscBlock, nz); OFF(DiscBlock, r2); OFF(DiscBlock, id);
    SIZE(PieceBlock); OFF(PieceBlock, ox); OFF(PieceBlock, oy); OFF(PieceBlock, oz); OFF(PieceBlock, wx);
    OFF(PieceBlock, wy); OFF(PieceBlock, wz); OFF(PieceBlock, t_end); OFF(PieceBlock, slot);
    OFF(PieceBlock, claim_lo); OFF(PieceBlock, claim_hi);
    SIZE(RayMapDisc); OFF(RayMapDisc, x); OFF(RayMapDisc, id); OFF(RayMapDisc, n); OFF(RayMapDisc, pad1);
    OFF(RayMapDisc, lo); OFF(RayMapDisc, pad2); OFF(RayMapDisc, hi); OFF(RayMapDisc, pad3);
    SIZE(ScRecord); OFF(ScRecord, org_tmax); OFF(ScRecord, dir_inv2);
    out[i++] = -1; /* end marker */
    /* after it, the alignment of the structs whose vector fields need more than 16 bytes */
    out[i++] = (int)__alignof__(BvhNode8);
    out[i++] = (int)__alignof__(InstanceBoxes);
}
