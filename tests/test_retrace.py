"""Suffix re-tracing: a path re-traced from any bounce equals the path traced
whole, bit for bit (the basis of incremental updates, DESIGN.md section 4)."""

import numpy as np
import pyopencl as cl

import oclgi
from oclgi.cl.layout import Segment
from oclgi.tracing.photon_trace import PhotonTracer
from test_instances import _rigid, _scene


def _store(engine, photons, seed=3, depth=8):
    tracer = PhotonTracer(engine.queue, engine.compiled, seed, depth, photons)
    return tracer, tracer.trace(0, photons)


def _read(engine, batch):
    return batch.read_segments(engine.queue), batch.read_path_len(engine.queue)


def _retrace(engine, tracer, batch, paths, starts):
    ctx = engine.ctx
    mf = cl.mem_flags
    pb = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.asarray(paths, np.int32))
    sb = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.asarray(starts, np.int32))
    tracer.retrace(batch, pb, sb, len(paths))


def test_suffix_retrace_reproduces_the_path(cornell, rng):
    photons = 20_000
    tracer, batch = _store(cornell, photons)
    segs, lens = _read(cornell, batch)
    # wreck the suffixes of 3,000 random paths, then re-trace them
    paths = rng.choice(photons, 3000, replace=False)
    starts = np.array([rng.integers(0, lens[p] + 1) for p in paths])  # b = len: re-trace past the end
    wrecked = segs.copy().reshape(photons, -1)
    for p, b in zip(paths, starts):
        wrecked[p, b:]["org"] = 7.0
        wrecked[p, b:]["power"] = -1.0
    cl.enqueue_copy(cornell.queue, batch.segments, wrecked.ravel())
    cl.enqueue_copy(cornell.queue, batch.path_len, np.zeros(photons, np.int32))
    _retrace(cornell, tracer, batch, paths, starts)
    again, lens2 = _read(cornell, batch)
    assert again.tobytes() == np.where(np.isin(np.arange(photons), paths)[:, None], segs.reshape(photons, -1),
                                       wrecked).tobytes()
    assert np.array_equal(lens2[paths], lens[paths])


def test_retrace_after_move_equals_fresh_trace(scenes_dir, rng):
    engine = oclgi.Engine(_scene(scenes_dir))
    photons = 10_000
    tracer, batch = _store(engine, photons)
    engine.move("bunny", _rigid(rng))
    _t2, fresh = _store(engine, photons)
    want, want_len = _read(engine, fresh)
    before, _ = _read(engine, batch)
    assert not np.array_equal(before, want)  # the move changed some paths
    # the first slot where each path differs: re-trace from there
    a = before.reshape(photons, -1).view(np.uint8).reshape(photons, 8, Segment.itemsize)
    b = want.reshape(photons, -1).view(np.uint8).reshape(photons, 8, Segment.itemsize)
    differs = (a != b).any(axis=2)
    changed = np.nonzero(differs.any(axis=1))[0]
    first = differs[changed].argmax(axis=1)
    assert 0 < len(changed) < photons
    _retrace(engine, tracer, batch, changed, first)
    got, got_len = _read(engine, batch)
    assert got.tobytes() == want.tobytes() and np.array_equal(got_len, want_len)
    engine.move("bunny", np.eye(4))
