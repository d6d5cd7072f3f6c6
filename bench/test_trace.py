"""Photon-tracing throughput, in path segments per second.

A segment is one ray of a light path: emission or a bounce up to the next hit
(or out of the scene). Tracing every segment is the first half of the
engine's work (the estimators consume the segments afterwards), so
segments/s is the engine's raw speed on a scene. It depends on the BVH
(closest hit per segment) and on memory: every path writes its ``max_depth``
segment slots, the unused ones zero-filled.

Each scene is traced with every scene tree (``oclgi.accel.bvh_build.QUALITIES``:
the binned SAH tree in 8-wide nodes with leaf blocks, "sah8b" the default,
and binary; the binary Morton LBVH), the same paths with each. ``-k sah``
runs the SAH layouts alone.

The workload is what ``Engine.irradiance`` does for its trace step: the same
``PhotonTracer``, the same batch size, the path lengths read back per batch.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from conftest import compiled_with

from oclgi.accel.bvh_build import QUALITIES
from oclgi.cl.layout import Segment
from oclgi.tracing.photon_trace import PhotonTracer

PATHS = 1_000_000
MAX_DEPTH = 16  # the engine's default
SEED = 1


def trace_all(engine, tracer, lens, n_paths):
    """Trace n_paths in the tracer's batches; the number of segments."""
    segments = 0
    for offset in range(0, n_paths, tracer.batch_paths):
        n = min(tracer.batch_paths, n_paths - offset)
        batch = tracer.trace(offset, n)
        cl.enqueue_copy(engine.queue, lens[:n], batch.path_len)  # waits for the trace
        segments += int(lens[:n].sum())
    return segments


@pytest.mark.parametrize("tree", QUALITIES)
@pytest.mark.parametrize("scene", ["cornell", "bunny_in_box", "sponza"])
def test_photon_trace(benchmark, request, scale, cores_used, scene, tree):
    engine = request.getfixturevalue(scene)
    n_paths = scale(PATHS)
    # The engine's batch rule: a batch's segment buffer fits in batch_bytes.
    batch = max(1, min(n_paths, engine.batch_bytes // (MAX_DEPTH * Segment.itemsize)))
    tracer = PhotonTracer(engine.queue, compiled_with(engine, tree), SEED, MAX_DEPTH, batch)
    lens = np.empty(batch, np.int32)

    benchmark.group = "photon trace"
    # The warmup round builds the kernel (PoCL compiles on first use).
    with cores_used():
        segments = benchmark.pedantic(trace_all, args=(engine, tracer, lens, n_paths), rounds=3, warmup_rounds=1)

    assert segments >= n_paths  # every path has at least its emission segment
    info = benchmark.extra_info
    info.update(scene=scene, tree=tree, triangles=engine.scene.n_triangles, paths=n_paths, max_depth=MAX_DEPTH,
                segments=segments, segments_per_path=round(segments / n_paths, 3))
    if benchmark.stats:  # absent under --benchmark-disable
        seconds = benchmark.stats.stats.median
        info.update(msegments_per_s=round(segments / seconds / 1e6, 3), kpaths_per_s=round(n_paths / seconds / 1e3, 1))
