"""The scene on the device: BVH, triangles in BVH order, materials, emitters.

Everything the kernels read is flattened here once, into the structs of
``oclgi.cl.layout``. Emitters are chosen with probability proportional to
their power (mean over RGB), and carry power / probability, so every photon
of a run carries about the same power and the fixed-point scale follows.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from ..accel.bvh_build import build_bvh
from ..cl.layout import Emitter, Material, Tri
from ..errors import OclgiError
from .scene import Scene

FIXED_BITS = 24  # see kernels/oclgi_types.h: one photon's power = 2^24 units
BVH_STACK_SIZE = 64


def _buffer(ctx, array, flags=cl.mem_flags.READ_ONLY):
    array = np.ascontiguousarray(array)
    if array.nbytes == 0:  # OpenCL refuses empty buffers
        array = np.zeros(1, dtype=array.dtype)
    return cl.Buffer(ctx, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)


class CompiledScene:
    def __init__(self, ctx: cl.Context, scene: Scene):
        self.ctx = ctx
        self.scene = scene
        t0 = time.perf_counter()
        v = scene.vertices[scene.faces]  # (F, 3, 3) float64
        bvh = build_bvh(v.min(axis=1), v.max(axis=1))
        if bvh.depth > BVH_STACK_SIZE:
            raise OclgiError(f"BVH depth {bvh.depth} exceeds the traversal stack ({BVH_STACK_SIZE})")
        self.bvh_depth = bvh.depth
        self.n_nodes = len(bvh.nodes)
        tris = np.zeros(len(v), dtype=Tri)
        vo = v[bvh.order]
        tris["v0"], tris["v1"], tris["v2"] = vo[:, 0], vo[:, 1], vo[:, 2]
        tris["id"] = bvh.order
        self.build_seconds = time.perf_counter() - t0

        normals = np.zeros((len(v), 4), np.float32)
        normals[:, :3] = scene.triangle_normals()
        self.areas = scene.triangle_areas().astype(np.float32)

        mats = np.zeros(len(scene.materials), dtype=Material)
        mats["albedo"] = [m.albedo for m in scene.materials]
        mats["emission"] = [m.emission for m in scene.materials]
        mats["survive"] = np.minimum(mats["albedo"].max(axis=1), 1.0)

        kind, tri, p, e1, e2, power = scene.emitters()
        weight = power.mean(axis=1)
        if not (weight.sum() > 0):
            raise OclgiError(f"{scene.name}: the emitters have zero power")
        prob = weight / weight.sum()
        cdf = np.cumsum(prob)
        cdf /= cdf[-1]
        em = np.zeros(len(kind), dtype=Emitter)
        em["kind"], em["tri"], em["p"], em["e1"], em["e2"] = kind, tri, p, e1, e2
        keep = prob > 0
        em["power"][keep] = power[keep] / prob[keep, None]
        self.n_emitters = len(em)
        self.total_power = power.sum(axis=0)  # RGB watts
        # Largest power any photon carries, times n_paths (fixed-point scale).
        self.photon_power_max = float(em["power"].max())

        self.nodes = _buffer(ctx, bvh.nodes)
        self.tris = _buffer(ctx, tris)
        self.tri_normals = _buffer(ctx, normals)
        self.tri_material = _buffer(ctx, scene.tri_material.astype(np.int32))
        self.materials = _buffer(ctx, mats)
        self.emitters = _buffer(ctx, em)
        self.emitter_cdf = _buffer(ctx, cdf.astype(np.float32))
        self.tri_areas = _buffer(ctx, self.areas)
        self.faces = _buffer(ctx, scene.faces.astype(np.int32))
        self.materials_host = mats
        # scene scale for ray offsets and the DETP tolerance
        self.eps = 1e-5 * scene.diagonal

    def fixed_scale(self, n_paths: int) -> float:
        """Fixed-point units per watt for a run of n_paths (oclgi_types.h)."""
        return float(2.0**FIXED_BITS / (self.photon_power_max / n_paths))
