"""The scene on the device: BVH, triangles in BVH order, materials, emitters.

Everything the kernels read is flattened here once, into the structs of
``oclgi.cl.layout``. Emitters are chosen with probability proportional to
their power (mean over RGB), and carry power / probability, so every photon
of a run carries about the same power and the fixed-point scale follows.
"""

from __future__ import annotations

import copy
import hashlib
import time

import numpy as np
import pyopencl as cl

from ..accel.bvh_build import build_bvh, scene_tree
from ..accel.bvh_leaf_blocks import leaf_blocks
from ..accel.bvh_wide import WIDE_STACK, collapse
from ..cl.constants import (BVH_STACK_SIZE, DELTA_KINDS, EMITTER_ENVMAP, EMITTER_IES, EMITTER_SKY,
                            EMITTER_TRIANGLE, FIXED_ONE)
from ..cl.layout import Emitter, Instance, Tri
from ..errors import OclgiError
from . import background, materials, shading_normals, textures
from .lights import emitter_rows, escaping_area_lights
from .pose import Pose, place_record
from .scene import OclgiWarning, Scene

F32_MAX = float(np.finfo(np.float32).max)


# The scene's and the movable objects' trees: built once per scene (a move
# changes a transform only), traversed by every ray of every kernel. The
# binned SAH tree collapsed into 8-wide nodes, its leaves as blocks of 4
# triangles (oclgi/accel/bvh_build.py QUALITIES has the binary trees too;
# bench/HISTORY.md, "Wide nodes", the other layouts it was measured
# against).
BVH_QUALITY = "sah8b"


def _buffer(ctx, array, flags=cl.mem_flags.READ_ONLY):
    array = np.ascontiguousarray(array)
    if array.nbytes == 0:  # OpenCL refuses empty buffers
        array = np.zeros(1, dtype=array.dtype)
    return cl.Buffer(ctx, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)


def _warn_escaping(scene: Scene) -> None:
    """One line when area lights emit only away from every surface (their
    light leaves the scene: flipped faces, most likely). A cheap exact test
    on the geometry (oclgi/scene/lights.py escaping_area_lights), once per
    compiled scene, rather than a look at the first batch's segments."""
    import warnings

    bad = escaping_area_lights(scene)
    if len(bad):
        names = sorted({scene.materials[m].name for m in scene.tri_material[bad]})
        warnings.warn(f"{scene.name}: {len(bad)} emitting triangle(s) (material {', '.join(map(repr, names))}) "
                      "emit only away from every surface: their light leaves the scene (flip the faces?)",
                      OclgiWarning, stacklevel=4)


class CompiledScene:
    """``bvh_quality`` names the objects' trees (oclgi/accel/bvh_build.py
    QUALITIES): "sah8b" (the default) builds the binned SAH tree and collapses
    it into 8-wide nodes (BvhNode8, oclgi/accel/bvh_wide.py), which the
    kernels traverse 8 child boxes at a time, with its leaves as blocks of 4
    triangles tested at once (TriBlock4, oclgi/accel/bvh_leaf_blocks.py);
    "sah" traverses the binary SAH tree itself (two boxes a node), "lbvh"
    the binary Morton tree.
    Every one gives the same hits up to which of two equally near triangles
    is found (the wide and binary layouts of one tree: the same bits but
    for such ties); ``n_nodes`` counts the traversed layout's nodes,
    ``n_binary_nodes`` the binary tree's."""

    shared_by_sessions = True  # sessions' close() leaves it alone (oclgi/cl/release.py)

    def __init__(self, ctx: cl.Context, scene: Scene, bvh_quality: str = BVH_QUALITY):
        self.ctx = ctx
        self.scene = scene
        self.bvh_quality = bvh_quality
        self.bounds = scene.bounds()  # of the geometry as loaded (estimators ask for it often)
        t0 = time.perf_counter()
        v = scene.vertices[scene.faces]  # (F, 3, 3) float64
        self._build_objects(v)
        self.build_seconds = time.perf_counter() - t0

        normals = np.zeros((len(v), 4), np.float32)
        normals[:, :3] = scene.triangle_normals()  # object space = world space until a move
        self.areas = scene.triangle_areas().astype(np.float32)

        tex_list, tex_index = [], {}
        for m in scene.materials:  # each texture once, however many materials share it
            if m.texture is not None and id(m.texture) not in tex_index:
                tex_index[id(m.texture)] = len(tex_list)
                tex_list.append(m.texture)
        self._tex_index = tex_index
        tex_records, texels = textures.pack(tex_list)
        uvmap = (textures.uv_maps(v, scene.tri_uv) if scene.tri_uv is not None and tex_list
                 else np.zeros((len(v), 8), np.float32))

        self._tables(scene)

        self.nodes = _buffer(ctx, np.concatenate([self._nodes.view(np.uint8), self._leaf_blocks.view(np.uint8)]))
        self.tris = _buffer(ctx, self._tris)
        self.object_normals = _buffer(ctx, normals)
        # the pose as loaded (the engine's; sessions take copies: Engine.posed)
        self.pose = Pose(self, self._loaded_records, normals)
        self.tri_material = _buffer(ctx, scene.tri_material.astype(np.int32))
        self.textures, self.texels = _buffer(ctx, tex_records), _buffer(ctx, texels)
        self.tri_uvmap = _buffer(ctx, uvmap)
        coloured = scene.tri_colour is not None and any(m.vertex_colours for m in scene.materials)
        colourmap = (textures.colour_maps(v, scene.tri_colour) if coloured else np.zeros((3 * len(v), 4), np.float32))
        self.tri_colourmap = _buffer(ctx, colourmap)
        # object space, as the uv maps; the camera alone reads them (oclgi/scene/shading_normals.py),
        # so they are not part of the fingerprint (no photon path depends on them)
        self.shading_host = shading_normals.normal_maps(v, scene.tri_vertex_normals)
        self.tri_shading = _buffer(ctx, self.shading_host)
        self.tri_object = _buffer(ctx, scene.tri_object.astype(np.int32))
        self.texels_host, self.uvmap_host, self.colourmap_host = texels, uvmap, colourmap
        self.tri_areas = _buffer(ctx, self.areas)
        self.faces = _buffer(ctx, scene.faces.astype(np.int32))
        # scene scale for ray offsets and the DETP tolerance
        self.eps = 1e-5 * scene.diagonal

    # -- what a parameter update changes (oclgi/scene_parameters.py) -------------------
    def _tables(self, scene: Scene) -> None:
        """The materials' and emitters' device tables of ``scene`` (its
        geometry this compiled scene's): all that a change of a material's
        parameters or of a light asks to rebuild."""
        ctx = self.ctx
        mats = materials.record(scene.materials, [self._tex_index.get(id(m.texture), -1) for m in scene.materials])
        self.materials, self.materials_host = _buffer(ctx, mats), mats
        rows = emitter_rows(scene)
        power = rows.power
        weight = power.mean(axis=1)
        if not (weight.sum() > 0):
            raise OclgiError(f"{scene.name}: the emitters have zero power")
        prob = weight / weight.sum()
        cdf = np.cumsum(prob)
        cdf /= cdf[-1]
        em = np.zeros(len(rows.kind), dtype=Emitter)
        em["kind"], em["tri"], em["p"], em["e1"], em["e2"] = rows.kind, rows.tri, rows.p, rows.e1, rows.e2
        em["a"], em["b"] = rows.a, rows.b
        # one buffer: the CDF, then the environment maps' and IES profiles'
        # tables (kernels/light.h; their records' tri is their offset in it)
        em["tri"][np.isin(rows.kind, (EMITTER_ENVMAP, EMITTER_IES))] += len(em)
        cdf_table = np.concatenate([cdf, rows.table]).astype(np.float32)
        keep = prob > 0
        # the largest power a photon path of each emitter carries (times
        # n_paths): its bound (oclgi/scene/lights.py; the power itself but
        # for spot lights and environment maps) over its probability
        photon_power = np.zeros_like(power)
        photon_power[keep] = rows.bound[keep] / prob[keep, None]
        self.n_emitters = len(em)
        self.total_power = power.sum(axis=0)  # RGB watts
        # phi_max, the largest power any photon path carries (times n_paths):
        # the device's unit of power (kernels/oclgi_types.h), so that a
        # photon's fixed-point power does not depend on the run's count.
        self.photon_power_max = float(photon_power.max())
        if not (np.isfinite(photon_power).all() and self.photon_power_max > 0):
            raise OclgiError(f"{scene.name}: the emitters' power ({weight.sum():.3g} W) is out of float32's range "
                             "on the device; scale the emission or intensity")
        em["power"] = photon_power / self.photon_power_max
        _warn_escaping(scene)

        self.emitters = _buffer(ctx, em)
        self.emitter_cdf = _buffer(ctx, cdf_table)
        self.emitters_host, self.emitter_cdf_host = em, cdf_table
        # each emitter's bound on its photons' power (RGB, float4 rows): the
        # intensity exact direct light reads (oclgi/estimators/detp_direct.py)
        bound = np.zeros((len(em), 4), np.float32)
        bound[:, :3] = rows.bound
        self.emitter_bound = _buffer(ctx, bound)
        # what a camera ray leaving the scene sees, and what the sky's exact
        # direct light reads (kernels/background.h): the lights' own
        bg, bg_texels = background.record(scene)
        self.background, self.background_texels = _buffer(ctx, bg), _buffer(ctx, bg_texels)
        self._spread_tables(scene, rows, weight)

    def _spread_tables(self, scene: Scene, rows, weight: np.ndarray) -> None:
        """The tables of the exact direct light of the emitters that are not
        deltas (area lights, the sky, an environment map; kernels/
        detp_direct.cl samples them): their ids and the CDF of their power
        (the photons' choice restricted to them), per emitter a float4 of
        its radiance (area lights: the material's emission) and its
        probability in that choice (0 for a delta light), the emitter of
        each triangle (-1: none) and the sky's emitter (-1: none)."""
        ctx = self.ctx
        spread = np.nonzero(~np.isin(rows.kind, DELTA_KINDS))[0].astype(np.int32)
        info = np.zeros((len(rows.kind), 4), np.float32)
        cdf = np.zeros(0, np.float32)
        if len(spread) and weight[spread].sum() > 0:
            p = weight[spread] / weight[spread].sum()
            info[spread, 3] = p
            cdf = np.cumsum(p)
            cdf = (cdf / cdf[-1]).astype(np.float32)
        area = np.nonzero(rows.kind == EMITTER_TRIANGLE)[0]
        emission = np.array([m.emission for m in scene.materials], np.float64).reshape(-1, 3)
        info[area, :3] = emission[scene.tri_material[rows.tri[area]]]
        tri_emitter = np.full(scene.n_triangles, -1, np.int32)
        tri_emitter[rows.tri[area]] = area
        sky = np.nonzero(np.isin(rows.kind, (EMITTER_SKY, EMITTER_ENVMAP)))[0]
        self.spread_ids, self.n_spread = _buffer(ctx, spread), len(cdf)
        self.spread_cdf, self.spread_info = _buffer(ctx, cdf), _buffer(ctx, info)
        self.tri_emitter = _buffer(ctx, tri_emitter)
        self.sky_emitter = int(sky[0]) if len(sky) else -1

    def with_scene(self, scene: Scene) -> "CompiledScene":
        """This compiled scene with the materials and lights of ``scene``
        (the same geometry, objects and textures, other parameters): the
        trees, triangles and pose shared, the tables new."""
        view = copy.copy(self)
        view.scene = scene
        view._tables(scene)
        return view

    def fingerprint(self) -> str:
        """A hash of everything a photon path depends on, as the device holds
        it: the tree and triangles (so the builder too), the poses, the
        materials, the emitters and the ray offset. Equal fingerprints trace
        equal paths; a checkpoint records it (oclgi/checkpoint.py)."""
        h = hashlib.sha256()
        for a in (self._nodes, self._leaf_blocks, self._tris, self.instances_host, self.materials_host,
                  self.texels_host, self.uvmap_host,
                  self.colourmap_host,
                  self.emitters_host,
                  self.emitter_cdf_host, self.scene.tri_material.astype(np.int32),
                  np.array([self.photon_power_max, self.eps], np.float64)):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    @property
    def scene_args(self) -> tuple:
        """The kernels' SCENE_ARGS (kernels/bvh.h): nodes (BvhNode records,
        or BvhNode8 records and their leaves' TriBlock4 records, as the
        instances' roots say), triangles, instances, count."""
        return (self.nodes, self.tris, self.instances, len(self.instances_host))

    def _build_objects(self, v):
        """One BVH per object, in one node array and one triangle array; one
        Instance per object, placed where the scene file put it (identity).
        A wide tree's Instance root is ~(its root node) (kernels/bvh.h)."""
        builder, wide = scene_tree(self.bvh_quality)
        ranges = self.scene.object_ranges()
        # the Tri records as (triangle, vertex, xyz + a word): v0 id v1 pad v2 pad
        nodes_all, tri_words = [], np.zeros((len(v), 3, 4), np.float32)
        v32 = v.astype(np.float32)  # rounding is monotone: the boxes of v32 are v's boxes rounded
        # the triangles' boxes: two element-wise ops each (min(axis=1) over 3 is ~3x slower)
        tri_lo = np.minimum(np.minimum(v32[:, 0], v32[:, 1]), v32[:, 2])
        tri_hi = np.maximum(np.maximum(v32[:, 0], v32[:, 1]), v32[:, 2])
        records = np.zeros(len(ranges), dtype=Instance)
        self.object_boxes = []
        n_nodes, depth, n_binary, stack_need = 0, 0, 0, 0
        queue = cl.CommandQueue(self.ctx)  # large SAH trees build on the device (oclgi/accel/bvh_sah_device.py)
        for k, (a, b) in enumerate(ranges):
            vk = v[a:b]
            bvh = build_bvh(tri_lo[a:b], tri_hi[a:b], quality=builder, queue=queue)
            n_binary += len(bvh.nodes)
            if wide:
                tree = collapse(bvh.nodes, node_offset=n_nodes, tri_offset=a)
                nodes, root = tree.nodes, ~n_nodes
                stack_need = max(stack_need, tree.stack_need)
                depth = max(depth, tree.depth)
            else:
                nodes = bvh.nodes.copy()
                inner = nodes["count"] == 0
                nodes["first"][inner] += n_nodes  # children in the joint node array
                nodes["first"][~inner] += a  # triangle runs in the joint triangle array
                root = n_nodes
                depth = max(depth, bvh.depth)
            tri_words[a:b, :, :3] = np.take(v32[a:b], bvh.order, axis=0)
            tri_words[a:b, 0, 3] = (a + bvh.order).astype(np.int32).view(np.float32)  # the id's bits
            inst = records[k]
            inst["root"], inst["first_tri"], inst["n_tris"] = root, a, b - a
            corners = vk.reshape(-1, 3)  # (a vertex per row: reducing one axis is faster than two)
            self.object_boxes.append((corners.min(axis=0), corners.max(axis=0)))
            place_record(inst, self.object_boxes[k], np.eye(4), self.scene.objects[k].name)
            nodes_all.append(nodes)
            n_nodes += len(nodes)
        tris = tri_words.reshape(len(v), -1).view(Tri)[:, 0]
        if not wide and depth > BVH_STACK_SIZE:
            raise OclgiError(f"BVH depth {depth} exceeds the traversal stack ({BVH_STACK_SIZE})")
        if wide and stack_need > WIDE_STACK:
            raise OclgiError(f"the wide BVH needs a traversal stack of {stack_need} entries, more than the "
                             f"kernels' {WIDE_STACK}")
        self.bvh_depth = depth  # levels of the traversed layout
        self.bvh_wide = wide
        self.bvh_stack_need = stack_need if wide else depth
        # the traversed layout's nodes: what the device reads and the fingerprint hashes
        self._nodes = np.concatenate(nodes_all)
        # a wide tree's leaves as triangle blocks, after the nodes in the nodes' buffer
        self._leaf_blocks = np.zeros(0, np.uint8)
        if wide:
            self._nodes, self._leaf_blocks = leaf_blocks(self._nodes, tris)
        self.n_nodes = len(self._nodes)
        self.n_binary_nodes = n_binary
        self._tris = tris
        self._loaded_records = records

    # -- the pose: what a move changes (oclgi/scene/pose.py) --------------------
    @property
    def instances(self) -> cl.Buffer:
        return self.pose.instances

    @property
    def instances_host(self) -> np.ndarray:
        return self.pose.instances_host

    @property
    def tri_normals(self) -> cl.Buffer:
        """World normals, float4 per triangle (the pose's)."""
        return self.pose.tri_normals

    def normals_kernel(self):
        """The kernel that turns a moved object's normals (kernels/instances.cl),
        made once: pyopencl creates a kernel object at every attribute access,
        and every move of every session calls it."""
        if getattr(self, "_normals_kernel", None) is None:
            from ..cl.programs import programs

            self._normals_kernel = programs(self.ctx).get("instances").instances_normals
        return self._normals_kernel

    def at(self, pose: Pose) -> "CompiledScene":
        """This scene seen at ``pose``: every tree, triangle and table shared,
        the instances and world normals the pose's."""
        view = copy.copy(self)
        view.pose = pose
        return view

    def set_transform(self, queue, obj: int, matrix) -> None:
        """Move object ``obj`` in this scene's pose (Pose.place)."""
        self.pose.place(queue, obj, matrix)

    def fixed_scale(self, n_paths: int) -> float:
        """Fixed-point units per watt of the sums of a run of n_paths: a
        photon's largest power, phi_max / n_paths watts, is 2^FIXED_BITS
        units (oclgi/cl/constants.py, oclgi_types.h). Only resolving divides
        by it: the sums themselves do not depend on n_paths."""
        scale = FIXED_ONE * n_paths / self.photon_power_max
        if not scale < F32_MAX:  # the kernels take it as a float32
            raise OclgiError(f"{self.scene.name}: the emitters' power ({self.photon_power_max:.3g} W per photon "
                             f"path) is too small for fixed-point sums of {n_paths:,} paths in float32; "
                             "scale the emission or intensity up")
        return scale
