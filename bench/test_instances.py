"""The top level with many movable objects: closest hit in Sponza with N
movable boxes, the instances' boxes tested 8 at a time (the default,
kernels/bvh.h scene_traverse) against one at a time (a build with
OCLGI_SCENE_FLAT_INSTANCES above N), alternating in one run.

The boxes (12 triangles, 1 m) stand at random places in the atrium, each
its own movable object; the rays are Sponza's surface-bounce rays (the
closest-hit benchmark's ``bounce`` set). Both ways give the same hits bit
for bit (asserted here; tests/test_instances.py holds them so); the time
is recorded, never asserted: ``extra_info`` has Mrays/s both ways, their
ratio, and the time against Sponza with no boxes.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from common import ROOT, box, timed
from conftest import lit_mesh
from oclgi.accel.bvh import closest_hits

sys.path.insert(0, str(ROOT / "tests"))  # the tests' ray sets
from rays import RAYS as RAY_SETS  # noqa: E402

RAYS = 1_000_000
ROUNDS = 5


def sponza_with_boxes(n: int):
    rng = np.random.default_rng(11)
    boxes = []
    for k in range(n):
        c = rng.uniform([-10.0, 1.0, -4.0], [10.0, 8.0, 4.0])
        v, f = box(c - 0.5, c + 0.5)
        boxes.append({"vertices": v, "faces": f, "movable": True, "name": f"box{k}", "albedo": [0.7, 0.7, 0.7]})
    return lit_mesh(f"sponza+{n}", "sponza-dabrovic/sponza.zip", [0.0, 6.0, 0.0], 50.0, *boxes)


@pytest.mark.parametrize("boxes", [0, 8, 32, 64])
def test_top_level(benchmark, scale, cores_used, sponza, boxes):
    engine = sponza_with_boxes(boxes) if boxes else sponza
    n = scale(RAYS)
    origins, dirs = RAY_SETS["bounce"](sponza.scene, np.random.default_rng(7), n)
    origins, dirs = origins.astype(np.float32), dirs.astype(np.float32)
    one_by_one = {"scene_flat_instances": 1 << 20}
    flat_seconds, flat_hits = [], []

    def run_flat():  # in pedantic's setup: the two alternate
        t, hits = timed(closest_hits, engine.queue, engine.compiled, origins, dirs, defines=one_by_one)
        flat_seconds.append(t)
        flat_hits[:] = [hits]

    benchmark.group = "top level: Sponza + N movable boxes"
    with cores_used():
        hits = benchmark.pedantic(closest_hits, args=(engine.queue, engine.compiled, origins, dirs),
                                  setup=run_flat, rounds=ROUNDS, warmup_rounds=1)
    tri, flat_tri = hits[3], flat_hits[0][3]
    assert np.array_equal(tri, flat_tri)
    hit = tri >= 0
    for a, b in zip(hits[:3], flat_hits[0][:3]):  # t, u, v of every hit
        assert np.array_equal(a[hit].view(np.int32), b[hit].view(np.int32))
    info = benchmark.extra_info
    info.update(boxes=boxes, instances=len(engine.compiled.instances_host), n_rays=n,
                hit_boxes=round(float(np.mean(tri >= sponza.scene.n_triangles)), 4))
    if benchmark.stats:
        grouped_rate = n / benchmark.stats.stats.median
        flat_rate = n / float(np.median(flat_seconds[1:]))
        info.update(grouped_mrays_per_s=round(grouped_rate / 1e6, 3), one_by_one_mrays_per_s=round(flat_rate / 1e6, 3),
                    grouped_over_one_by_one=round(grouped_rate / flat_rate, 3))
