"""DETP methods timed on one workload: plain DETP and its accelerations.

The Cornell box, 2 x 10^4 random surface points, 10^5 photon paths; each
method's estimate (tracing excluded) is timed, with its exact work counts
(t, u, node visits) and its speed-up over plain DETP in ``extra_info``. All
methods give identical sums (tests/ checks it; here it is asserted once more
on the timed runs). ``bench/detp_study.py`` sweeps sizes, Q and orderings.
"""

from __future__ import annotations

import numpy as np
import pytest

from common import surface_points
from oclgi.estimators import METHODS

DETP_METHODS = [m for m in METHODS if m.startswith("detp")]
_plain = {}


@pytest.fixture(scope="module")
def workload(cornell, scale):
    return surface_points(cornell.scene, scale(20_000), np.random.default_rng(11)), scale(100_000)


@pytest.mark.parametrize("method", DETP_METHODS)
def test_detp_method(benchmark, cornell, workload, cores_used, method):
    points, photons = workload
    radius = 0.01 * cornell.scene.diagonal

    def run():
        return cornell.irradiance(points, method=method, photons=photons, radius=radius, count_work=True)

    benchmark.group = "DETP methods, Cornell box"
    with cores_used():
        est = benchmark.pedantic(run, rounds=3 if method == "detp" else 5, warmup_rounds=1)
    seconds = est.stats.seconds["estimate"]
    if method == "detp":
        _plain["acc"], _plain["seconds"] = est.accumulators, seconds
    elif "acc" in _plain:
        assert np.array_equal(est.accumulators, _plain["acc"])
        benchmark.extra_info["speedup_over_plain"] = round(_plain["seconds"] / seconds, 2)
    benchmark.extra_info.update(method=method, points=len(points), segments=est.stats.segments,
                                estimate_seconds=round(seconds, 4), **est.work)
