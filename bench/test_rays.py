"""Closest-hit ray queries: oclgi's BVH against Embree, same mesh, same rays.

Photon tracing is one closest-hit query per segment, so rays/s of the BVH
bounds the whole engine; Embree is the reference for what a CPU can do.

Both sides run end to end from numpy arrays to numpy arrays:
``oclgi.accel.bvh.closest_hits`` (the arrays wrapped as device buffers,
read in place on a CPU device, the kernel, the hits mapped back) on the
OpenCL device, and embreex's ``EmbreeScene.run`` (Embree 4, one ``rtcIntersect1``
per ray). ``run`` releases the GIL, so Embree gets as many threads, each on
a slice of the rays, as the OpenCL CPU device has compute units: both use the
whole CPU (on a GPU device, one thread per core of the machine). Embree's BVH is built before timing, as oclgi's is.

Two ray sets of 10^6 rays each:
- ``incoherent``: origins uniform in the mesh's bounding box, directions
  uniform on the sphere (the worst case for any BVH);
- ``bounce``: origins on the surface (area-uniform), lifted off it along the
  normal of a random side, directions cosine-distributed about that normal,
  as the rays of diffuse photon bounces are.

Each runs on every scene tree (``oclgi.accel.bvh_build.QUALITIES``): the
binned SAH tree in 8-wide nodes with its leaves as blocks of 4 triangles
(the default, "sah8b"), the same tree traversed binary ("sah"), and the
binary Morton LBVH ("lbvh"), with the traversal work of each counted
exactly (nodes visited and triangles tested per ray,
``oclgi.accel.bvh.traversal_work``; a wide node tests 8 boxes, a binary one
2): the count is what a tree changes, the time what it costs on this
machine. ``-k sah`` runs the SAH layouts alone.

Both must agree on hit or miss for more than 99% of the rays (float
intersectors may differ on grazing rays); nothing is asserted about time.
The rays where Embree finds a nearer hit than oclgi are counted
(``nearer_hit_missed``): they are where light could leak through a mesh.
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from oclgi.accel.bvh import closest_hits, traversal_work
from oclgi.accel.bvh_build import QUALITIES
from conftest import compiled_with

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' ray sets
from rays import RAYS as RAY_SETS  # noqa: E402

RAYS = 1_000_000
ROUNDS = 5




class Embree:
    """An Embree scene of the same triangles, queried on ``threads`` threads."""

    def __init__(self, scene, threads):
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcs.EmbreeScene()
        # (F, 3, 3) vertices in scene order, so primID is oclgi's triangle id
        TriangleMesh(self.scene, scene.vertices[scene.faces].astype(np.float32))
        self.scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))  # builds the BVH
        self.threads = threads

    def closest(self, origins, dirs):
        """(t, primID) per ray; primID -1 on a miss."""
        parts = np.array_split(np.arange(len(origins)), self.threads)
        slices = [slice(p[0], p[-1] + 1) for p in parts if len(p)]
        with ThreadPoolExecutor(len(slices)) as pool:
            runs = list(pool.map(lambda s: self.scene.run(origins[s], dirs[s], output=1), slices))
        return np.concatenate([r["tfar"] for r in runs]), np.concatenate([r["primID"] for r in runs])


def embree_threads(device):
    """Embree gets the cores oclgi uses: the OpenCL CPU device's compute units,
    or every core of the machine when oclgi runs on a GPU (its compute units
    are the GPU's multiprocessors, not threads Embree could use)."""
    import pyopencl as cl

    if device.type & cl.device_type.CPU:
        return device.max_compute_units
    return os.cpu_count() or 1


@pytest.mark.parametrize("tree", QUALITIES)
@pytest.mark.parametrize("rays", list(RAY_SETS))
@pytest.mark.parametrize("scene", ["bunny", "sponza"])
def test_closest_hit(benchmark, request, scale, cores_used, scene, rays, tree):
    engine = request.getfixturevalue(scene)
    compiled = compiled_with(engine, tree)
    n = scale(RAYS)
    origins, dirs = RAY_SETS[rays](engine.scene, np.random.default_rng(7), n)
    origins, dirs = origins.astype(np.float32), dirs.astype(np.float32)
    embree = Embree(engine.scene, embree_threads(engine.queue.device))

    # Embree runs in pedantic's setup, just before each oclgi round: the two
    # alternate, so a change in the load of a shared machine hits both alike.
    embree_seconds, embree_hits = [], []

    def run_embree():
        t0 = time.perf_counter()
        embree_hits[:] = [embree.closest(origins, dirs)]
        embree_seconds.append(time.perf_counter() - t0)

    benchmark.group = f"closest hit: {scene}"
    with cores_used():
        t, _u, _v, tri = benchmark.pedantic(closest_hits, args=(engine.queue, compiled, origins, dirs),
                                            setup=run_embree, rounds=ROUNDS, warmup_rounds=1)
    t_embree, prim = embree_hits[0]

    agree = float(np.mean((tri >= 0) == (prim >= 0)))
    # A nearer hit that oclgi missed: a ray through an edge shared by two
    # triangles can slip between them with Moller-Trumbore in float, not with
    # Embree's Pluecker test, which is watertight along shared edges.
    # The tolerance absorbs float noise in t (both hit the same triangle).
    missed = (prim >= 0) & ~(t <= t_embree * (1 + 1e-4) + 1e-6 * engine.scene.diagonal)
    info = benchmark.extra_info
    nodes, tests = traversal_work(engine.queue, compiled, origins, dirs)
    info.update(scene=scene, rays=rays, tree=tree, n_rays=n, triangles=engine.scene.n_triangles,
                tree_nodes=compiled.n_nodes, tree_depth=compiled.bvh_depth, wide=compiled.bvh_wide,
                binary_nodes=compiled.n_binary_nodes,
                nodes_per_ray=round(float(nodes.mean()), 2), tests_per_ray=round(float(tests.mean()), 2),
                hit_fraction=round(float(np.mean(tri >= 0)), 4), hit_agreement=round(agree, 6),
                same_triangle=round(float(np.mean(tri == prim)), 6), nearer_hit_missed=int(missed.sum()),
                embree_threads=embree.threads)
    if benchmark.stats:  # absent under --benchmark-disable
        oclgi_rate = n / benchmark.stats.stats.median
        embree_rate = n / float(np.median(embree_seconds[1:]))  # [0] was the warmup round
        info.update(oclgi_mrays_per_s=round(oclgi_rate / 1e6, 3), embree_mrays_per_s=round(embree_rate / 1e6, 3),
                    ratio_oclgi_over_embree=round(oclgi_rate / embree_rate, 3))
    assert agree > 0.99
