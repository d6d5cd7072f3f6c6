"""The device SAH builder (oclgi/accel/bvh_sah_device.py) against the numpy
builder (oclgi/accel/bvh_sah.py), its specification: the same tree, node
for node and byte for byte, with the same primitive order."""

import numpy as np
import pytest

import oclgi
from oclgi.accel.bvh_build import build_bvh
from oclgi.accel.bvh_sah import build_sah
from oclgi.accel.bvh_sah_device import DEVICE_MIN_PRIMITIVES, build_sah_device


@pytest.fixture(scope="module")
def queue(cl_env):
    return cl_env[1]


def _assert_same_tree(queue, lo, hi, leaf_size=4, **kw):
    ref = build_sah(lo, hi, leaf_size)
    dev = build_sah_device(queue, lo, hi, leaf_size, **kw)
    assert dev.depth == ref.depth and len(dev.nodes) == len(ref.nodes)
    assert dev.nodes.tobytes() == ref.nodes.tobytes()
    assert np.array_equal(dev.order, ref.order) and dev.order.dtype == ref.order.dtype
    return dev


def _triangle_boxes(v):
    v = np.asarray(v, np.float32)
    return v.min(axis=1), v.max(axis=1)


@pytest.mark.parametrize("n, leaf_size", [(1, 4), (4, 4), (5, 4), (37, 1), (3000, 4), (3000, 8), (40_000, 4)])
def test_random_triangles(queue, n, leaf_size):
    rng = np.random.default_rng(n)
    c = rng.random((n, 1, 3))
    _assert_same_tree(queue, *_triangle_boxes(c + 0.01 * (rng.random((n, 3, 3)) - 0.5)), leaf_size)


def test_clustered_boxes_split_unevenly(queue):
    rng = np.random.default_rng(3)
    c = rng.random((20_000, 3)) ** 3
    _assert_same_tree(queue, c, c + rng.random((20_000, 3)) * 0.01)


@pytest.mark.parametrize("mesh", ["stanford-bunny/bun_zipper.ply", "sponza-dabrovic/sponza.zip"])
def test_real_meshes(queue, scenes_dir, mesh):
    scene = oclgi.load_dict({"mesh": [{"path": str(scenes_dir / mesh)}],
                             "point_light": [{"position": [0, 0.3, 0], "intensity": [1, 1, 1]}]})
    _assert_same_tree(queue, *_triangle_boxes(scene.vertices[scene.faces]))


def test_median_fallbacks(queue, monkeypatch):
    """The host-halved nodes: coincident centroids (all of them, and a
    cluster of them inside a larger tree), and every node from MEDIAN_DEPTH
    on (lowered to reach it)."""
    import oclgi.accel.bvh_sah as bvh_sah

    same = np.zeros((1000, 3), np.float32)
    _assert_same_tree(queue, same, same + 1)
    rng = np.random.default_rng(5)
    lo = rng.random((5000, 3)).astype(np.float32)
    lo[:700] = 0.25  # 700 equal boxes
    _assert_same_tree(queue, lo, lo + 0.01)
    monkeypatch.setattr(bvh_sah, "MEDIAN_DEPTH", 3)
    _assert_same_tree(queue, lo, lo + 0.01)


# 1 and 7 against the launches' own size (64 where they name none: every other test runs it); 64 itself in the full suite
@pytest.mark.parametrize("local_size", [1, 7, pytest.param(64, marks=pytest.mark.full)])
def test_work_group_size_changes_nothing(queue, local_size):
    rng = np.random.default_rng(9)
    c = rng.random((10_000, 3)) ** 2
    _assert_same_tree(queue, c, c + 0.02, local_size=local_size)


def test_build_bvh_picks_the_device_for_large_trees(queue, monkeypatch):
    """build_bvh with a queue builds SAH trees of DEVICE_MIN_PRIMITIVES boxes
    or more on the device, smaller ones and queue-less calls with numpy."""
    import oclgi.accel.bvh_build as bvh_build

    calls = []
    monkeypatch.setattr(bvh_build, "build_sah_device", lambda *a: calls.append("device") or build_sah_device(*a))
    monkeypatch.setattr(bvh_build, "build_sah", lambda *a: calls.append("numpy") or build_sah(*a))
    rng = np.random.default_rng(1)
    for n, q in [(DEVICE_MIN_PRIMITIVES, queue), (DEVICE_MIN_PRIMITIVES - 1, queue), (DEVICE_MIN_PRIMITIVES, None)]:
        c = rng.random((n, 3))
        build_bvh(c, c + 0.01, quality="sah", queue=q)
    assert calls == ["device", "numpy", "numpy"]
