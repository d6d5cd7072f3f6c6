"""Same seed, same bits: DESIGN.md section 2.

Accumulators are 64-bit fixed-point sums of per-segment quantised powers,
and randomness is a pure function of (seed, path, bounce, dimension), so a
result must not depend on the run, the work-group size, the number of
threads, or how the photons are split into batches.
"""

import hashlib
import os
import subprocess
import sys

import numpy as np
import pytest

import oclgi


@pytest.fixture(scope="module")
def cornell(scenes_dir):
    return oclgi.load_file(scenes_dir / "cornell_box.toml")


def _run(scene, method, **engine_args):
    engine = oclgi.Engine(scene, **engine_args)
    pts = engine.camera_points(width=24, height=24)
    est = engine.irradiance(pts, method=method, photons=30_000, radius=0.1)
    return est.accumulators


@pytest.mark.parametrize("method", ["detp", "impact"])
def test_work_group_size_does_not_matter(cornell, method):
    ref = _run(cornell, method, local_size=1)
    for ls in (7, 32, 128):
        assert np.array_equal(_run(cornell, method, local_size=ls), ref)


@pytest.mark.parametrize("method", ["detp", "impact"])
def test_batches_do_not_matter(cornell, method):
    """A run split into many small batches equals one batch, bit for bit."""
    whole = _run(cornell, method)
    split = _run(cornell, method, batch_bytes=16 * 48 * 1000)  # 1,000 paths per batch
    assert np.array_equal(split, whole)


def test_different_seed_differs(cornell):
    engine = oclgi.Engine(cornell)
    pts = engine.camera_points(width=16, height=16)
    a = engine.irradiance(pts, photons=20_000, seed=1).accumulators
    assert not np.array_equal(a, engine.irradiance(pts, photons=20_000, seed=2).accumulators)


_SCRIPT = """
import hashlib, sys
import oclgi
scene = oclgi.load_file(sys.argv[1])
engine = oclgi.Engine(scene)
pts = engine.camera_points(width=24, height=24)
for method in ("detp", "impact"):
    acc = engine.irradiance(pts, method=method, photons=30_000, radius=0.1).accumulators
    print(method, hashlib.sha256(acc.tobytes()).hexdigest())
"""


def test_thread_count_does_not_matter(scenes_dir, cornell):
    """POCL_MAX_PTHREAD_COUNT=1 and =2 give identical accumulators, and the
    same seed gives this process's run the same bits again."""
    outs = []
    for threads in ("1", "2"):
        env = dict(os.environ, POCL_MAX_PTHREAD_COUNT=threads)
        r = subprocess.run([sys.executable, "-c", _SCRIPT, str(scenes_dir / "cornell_box.toml")],
                           env=env, capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
        outs.append(r.stdout)
    assert outs[0] == outs[1] and outs[0].count("\n") == 2
    # and equal to this process's own runs
    for method in ("detp", "impact"):
        acc = _run(cornell, method)
        assert acc.any() and f"{method} {hashlib.sha256(acc.tobytes()).hexdigest()}" in outs[0]
