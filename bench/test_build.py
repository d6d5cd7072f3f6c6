"""BVH build time for a million triangles (``oclgi.accel.bvh_build.build_bvh``),
for the builders: the Morton LBVH (the overlap trees', numpy), the binned SAH
in numpy (``bvh_sah.py``, the specification) and on the OpenCL device
(``bvh_sah_device.py``, the same tree: the scene's and the movable objects'
trees of 20,000 triangles or more); and the time to collapse the SAH tree
into the scene's 8-wide nodes (``oclgi.accel.bvh_wide.collapse``) and the
leaves into blocks of 4 triangles (``bvh_leaf_blocks.leaf_blocks``),
which a scene compile adds to the SAH build; ``test_scene_tree`` times the
three steps of the default scene tree (``sah8b``) together, and
``test_mesh_build`` both SAH builders on the bunny and Sponza.

The build runs each time a scene is compiled, so it is the start-up cost of
every run; the target is at most 1 s for 10^6 triangles on a 2-core machine
(the default scene tree, all steps). Nothing is asserted about time. The tree's
SAH cost (inner node areas plus leaf areas times their primitives, over the
root's area) is recorded with it: what the SAH builder's extra time buys.

The triangles are synthetic: small random triangles (edges up to 1% of the
box) with centres uniform in the unit cube. The builder's cost is a sort plus
one vector pass per tree level, so it depends on the count far more than on
the shape. Embree's build of the same triangles (embreex's default scene
flags, all threads) is recorded once as a reference.
"""

from __future__ import annotations

import time

import numpy as np

import pytest

import oclgi
from oclgi.accel.bvh_build import BUILDERS, build_bvh
from oclgi.accel.bvh_leaf_blocks import leaf_blocks
from oclgi.accel.bvh_sah import build_sah
from oclgi.accel.bvh_sah_device import build_sah_device
from oclgi.accel.bvh_wide import collapse
from oclgi.cl.layout import Tri
from oclgi.scene.compiled import BVH_STACK_SIZE

TRIANGLES = 1_000_000


@pytest.fixture(scope="module")
def queue():
    from oclgi.cl.device import create_context

    return create_context()[1]


def random_triangles(n, rng):
    centre = rng.random((n, 1, 3))
    return (centre + 0.01 * (rng.random((n, 3, 3)) - 0.5)).astype(np.float32)


def embree_build_seconds(tris):
    """Embree's BVH build alone: embreex builds on the first query. Copying
    the triangles into Embree (``TriangleMesh``, about a second here) is left
    out, as ``build_bvh`` gets its boxes ready-made."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, tris)
    t0 = time.perf_counter()
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
    return time.perf_counter() - t0


def sah_cost(nodes) -> float:
    e = np.maximum(nodes["hi"] - nodes["lo"], 0)
    a = e[:, 0] * e[:, 1] + e[:, 1] * e[:, 2] + e[:, 2] * e[:, 0]
    leaf = nodes["count"] > 0
    return float((a[~leaf].sum() + (a[leaf] * nodes["count"][leaf]).sum()) / a[0])


@pytest.mark.parametrize("quality", [*BUILDERS, "sah-device"])
def test_bvh_build(benchmark, scale, cores_used, queue, quality):
    n = scale(TRIANGLES)
    tris = random_triangles(n, np.random.default_rng(3))
    lo, hi = tris.min(axis=1), tris.max(axis=1)

    benchmark.group = "bvh build"
    # numpy builds on one core, the device on all (PoCL's threads), as does Embree's reference build
    with cores_used():
        if quality == "sah-device":  # the first call (warm-up round) builds the program
            bvh = benchmark.pedantic(build_sah_device, args=(queue, lo, hi), rounds=3, warmup_rounds=1)
        else:
            bvh = benchmark.pedantic(build_bvh, args=(lo, hi), kwargs=dict(quality=quality), rounds=3,
                                     warmup_rounds=1)

    # The tree must be usable: every triangle in one leaf, depth within the
    # traversal stack of the kernels.
    assert np.array_equal(np.sort(bvh.order), np.arange(n))
    assert bvh.depth <= BVH_STACK_SIZE
    info = benchmark.extra_info
    info.update(quality=quality, triangles=n, nodes=len(bvh.nodes), depth=bvh.depth,
                sah_cost=round(sah_cost(bvh.nodes), 2),
                embree_build_s=round(embree_build_seconds(tris), 3))
    if benchmark.stats:  # absent under --benchmark-disable
        info["seconds"] = round(benchmark.stats.stats.median, 3)
        info["mtris_per_s"] = round(n / benchmark.stats.stats.median / 1e6, 3)


def test_wide_collapse(benchmark, scale, cores_used, queue):
    """The SAH tree of the same triangles into 8-wide nodes."""
    n = scale(TRIANGLES)
    tris = random_triangles(n, np.random.default_rng(3))
    bvh = build_sah_device(queue, tris.min(axis=1), tris.max(axis=1))

    benchmark.group = "bvh build"
    with cores_used():
        wide = benchmark.pedantic(collapse, args=(bvh.nodes,), rounds=3, warmup_rounds=1)

    assert len(wide.nodes) < len(bvh.nodes) // 4
    info = benchmark.extra_info
    info.update(triangles=n, binary_nodes=len(bvh.nodes), wide_nodes=len(wide.nodes), wide_depth=wide.depth,
                binary_depth=bvh.depth, stack_need=wide.stack_need)
    if benchmark.stats:
        info["seconds"] = round(benchmark.stats.stats.median, 3)


def _records(tris, bvh):
    records = np.zeros(len(tris), dtype=Tri)
    for k in range(3):
        records[f"v{k}"] = tris[bvh.order, k]
    records["id"] = bvh.order
    return records


def test_leaf_blocks(benchmark, scale, cores_used, queue):
    """The 8-wide nodes of the same triangles with their leaves as blocks
    of 4 triangles (the default scene tree's last step)."""
    n = scale(TRIANGLES)
    tris = random_triangles(n, np.random.default_rng(3))
    bvh = build_sah_device(queue, tris.min(axis=1), tris.max(axis=1))
    wide = collapse(bvh.nodes)
    records = _records(tris, bvh)

    benchmark.group = "bvh build"
    with cores_used():
        nodes, blocks = benchmark.pedantic(leaf_blocks, args=(wide.nodes, records), rounds=3, warmup_rounds=1)

    assert len(blocks) >= n / 4
    info = benchmark.extra_info
    info.update(triangles=n, wide_nodes=len(wide.nodes), leaf_blocks=len(blocks))
    if benchmark.stats:
        info["seconds"] = round(benchmark.stats.stats.median, 3)


def test_scene_tree(benchmark, scale, cores_used, queue):
    """10^6 triangles compiled into a scene (``CompiledScene``, the default
    tree ``sah8b``): ``build_seconds`` is the trees' part, the device SAH
    build, the collapse into 8-wide nodes, the triangle records in BVH order
    and the leaf blocks; the rest is the scene's other tables and buffers."""
    from oclgi.scene.compiled import CompiledScene

    n = scale(TRIANGLES)
    tris = random_triangles(n, np.random.default_rng(3))
    scene = oclgi.load_dict({"mesh": [{"vertices": tris.reshape(-1, 3).astype(np.float64),
                                       "faces": np.arange(3 * n).reshape(n, 3)}],
                             "point_light": [{"position": [0.5, 2.0, 0.5], "intensity": [1.0, 1.0, 1.0]}]})
    seconds = []

    def compile_scene():
        compiled = CompiledScene(queue.context, scene)
        seconds.append(compiled.build_seconds)
        return compiled

    benchmark.group = "scene tree"
    with cores_used():
        compiled = benchmark.pedantic(compile_scene, rounds=3, warmup_rounds=1)
    assert compiled.bvh_quality == "sah8b" and compiled.n_binary_nodes >= n / 4
    info = benchmark.extra_info
    info.update(triangles=len(scene.faces), trees_s=round(float(np.median(seconds[1:])), 3),
                trees_min_s=round(min(seconds[1:]), 3))


@pytest.mark.parametrize("builder", ["numpy", "device"])
@pytest.mark.parametrize("mesh", ["bunny", "sponza"])
def test_mesh_build(benchmark, cores_used, request, queue, mesh, builder):
    """The SAH tree of a real mesh (the bunny, 69k triangles; Sponza, 66k),
    by each builder: where the device one starts to pay."""
    scene = request.getfixturevalue(mesh).scene
    v = scene.vertices[scene.faces]
    lo, hi = v.min(axis=1).astype(np.float32), v.max(axis=1).astype(np.float32)

    benchmark.group = "mesh sah build"
    with cores_used():
        if builder == "device":
            bvh = benchmark.pedantic(build_sah_device, args=(queue, lo, hi), rounds=5, warmup_rounds=1)
        else:
            bvh = benchmark.pedantic(build_sah, args=(lo, hi), rounds=5, warmup_rounds=1)
    assert np.array_equal(np.sort(bvh.order), np.arange(len(v)))
    benchmark.extra_info.update(mesh=mesh, builder=builder, triangles=len(v), nodes=len(bvh.nodes))
