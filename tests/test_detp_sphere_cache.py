"""DETP with a sphere cache: identical to plain DETP, and its counted cost.

Exactness (DESIGN.md 3, "all DETP variants select exactly the same
segments"): on the Cornell box and the bunny scene, for the three radius
fractions, for the orders hilbert/morton/none crossed with q = 0.5, 2/3,
0.8, with and without the emitted segments, for run lengths from 1 to all
points, for several work-group sizes, with list overflows forced, with list
0 cut into pieces (a tiny memory budget), for camera points with misses,
and on adversarial segments (grazing, ending on a disc's plane, escaping,
far from the origin), the fixed-point accumulators equal plain DETP's bit
for bit.

Counts: t and u are those of the algorithm (a numpy float64 replay of it
gives the same numbers up to a few borderline float32 tests; without inner
spheres they are exactly n_R and n_P n_R), do not depend on overflow reruns
or pieces, and in the
thesis' setting (points filling a volume, Hilbert order, discs much smaller
than the point spacing) t + u is least for Q in [0.60, 0.72] over the sweep
0.40 .. 0.90 (García 2006's model puts it at 2/3).
"""

import numpy as np
import pytest

import oclgi
from exactness import (DETP_PHOTONS, RADIUS_FRACTIONS, check_adversarial, check_camera_misses, check_same,
                       surface_points)
from oclgi.accel import ordering
from oclgi.errors import OclgiError
from oclgi.estimators import detp_sphere_cache as sc

METHOD = "detp_sphere_cache"  # the `same_as_plain` fixture's (conftest.py)
PHOTONS = DETP_PHOTONS  # the shared `plain` fixture's (conftest.py)


def run(engine, pts, frac, **kw):
    return engine.irradiance(pts, method=METHOD, radius=frac * engine.scene.diagonal, photons=PHOTONS, **kw)


# -- exactness -------------------------------------------------------------------

@pytest.mark.parametrize("frac", RADIUS_FRACTIONS)
@pytest.mark.parametrize("scene", ["cornell", "bunny"])
def test_same_as_plain(same_as_plain, scene, frac):
    """Every order with every q."""
    for order in ordering.METHODS:
        for q in (0.5, 2 / 3, 0.8):
            same_as_plain(scene, frac, order=order, q=q)


@pytest.mark.parametrize("frac", RADIUS_FRACTIONS)
# the emitted segments left out is one flag of the same walk: the bunny in make test, the box as well in the full suite
@pytest.mark.parametrize("scene", [pytest.param("cornell", marks=pytest.mark.full), "bunny"])
def test_same_as_plain_without_emitted(same_as_plain, scene, frac):
    same_as_plain(scene, frac, count_emitted=False)


def test_run_lengths(engines, points, plain):
    """From one point per run (every point a cold start) to one run for all:
    the same sums; shorter runs re-use less, so they count more tests."""
    e, frac = engines["cornell"], RADIUS_FRACTIONS[1]
    ref = plain("cornell", frac)
    t = {}
    n = len(points["cornell"])
    for run_length in (1, 5, 64, 333, n):
        est = run(e, points["cornell"], frac, run_length=run_length, count_work=True)
        check_same(ref, est.accumulators, f"run_length {run_length}")
        t[run_length] = est.work["t"]
    assert t[1] > t[5] > t[64] > t[n], t


# 1 and 7 against the launches' own size (64 where they name none: every other test runs it); 64 itself in the full suite
@pytest.mark.parametrize("local_size", [1, 7, pytest.param(64, marks=pytest.mark.full)])
def test_work_group_sizes(engines, same_as_plain, local_size):
    same_as_plain("cornell", RADIUS_FRACTIONS[2], engine=oclgi.Engine(engines["cornell"].scene, local_size=local_size),
                  run_length=50)


def test_camera_points_with_misses(engines):
    """Camera points (a surface seen in scanline order, background pixels with zero normals)."""
    check_camera_misses(engines["cornell"], METHOD, 32, [{"order": order} for order in ordering.METHODS])


def test_overflow_reruns_are_exact(engines, points, plain, monkeypatch):
    """Lists far larger than the capacity: runs stop, resume with more room,
    and end with the same sums and the same counts as without overflow; over
    several batches (the later ones sized from the first's peak)."""
    e, frac = engines["bunny"], RADIUS_FRACTIONS[1]
    ref = run(e, points["bunny"], frac, count_work=True)
    caps = []
    real = sc.DetpSphereCache._initial_cap

    def tiny(self, n0):
        caps.append(real(self, n0))
        return 40

    monkeypatch.setattr(sc.DetpSphereCache, "_initial_cap", tiny)
    got = run(e, points["bunny"], frac, count_work=True, run_length=100)
    check_same(plain("bunny", frac), got.accumulators, "forced overflow")
    monkeypatch.undo()
    assert got.work == run(e, points["bunny"], frac, count_work=True, run_length=100).work
    assert caps and all(c > 40 for c in caps)  # the overflow path did run
    # several batches: 1,000 paths each
    small = oclgi.Engine(e.scene, batch_bytes=8 * 48 * 1000)
    split = small.irradiance(points["bunny"], method=METHOD, radius=frac * e.scene.diagonal, photons=PHOTONS)
    check_same(ref.accumulators, split.accumulators, "20 batches")


def test_pieces_when_lists_exceed_the_memory(engines, points, plain, monkeypatch):
    """A scratch budget far below what the lists need: list 0 is processed in
    pieces (each run resuming where the last piece left it), with the same
    sums and the same counts."""
    e, frac = engines["cornell"], RADIUS_FRACTIONS[0]
    ref = run(e, points["cornell"], frac, count_work=True, run_length=300)
    monkeypatch.setattr(sc, "SCRATCH_BYTES", sc.ENTRY_BYTES * 3000)  # ~1/10 of one run's peak
    got = run(e, points["cornell"], frac, count_work=True, run_length=300)
    assert got.estimator.scratch_bytes == sc.ENTRY_BYTES * 3000
    check_same(plain("cornell", frac), got.accumulators, "pieces")
    assert got.work == ref.work


@pytest.mark.parametrize("offset", [0.0, 1000.0])
@pytest.mark.parametrize("count_emitted", [True, False])
def test_adversarial_segments(engines, count_emitted, offset):
    check_adversarial(engines["cornell"], METHOD, 8, count_emitted,
                      [{}, {"q": 0.5, "order": "none", "run_length": 7}, {"q": 0.9, "order": "morton"}],
                      n_discs=300, n_paths=10_000, offset=offset)


# -- counts ------------------------------------------------------------------------

def reference_counts(xyz, perm, segs, ext, c0, radii, d, run_length):
    """(t, u) of the sphere cache replayed in numpy float64 (tests only)."""
    w = segs["dir"].astype(np.float64)
    wl = np.linalg.norm(w, axis=1)
    keep = wl > 0
    o = segs["org"].astype(np.float64)[keep]
    u = w[keep] / wl[keep, None]
    length = (segs["t_end"].astype(np.float64)[keep] + np.float32(ext)) * wl[keep]

    def meets(c, r, idx):
        v = c - o[idx]
        s = np.clip(np.einsum("ij,ij->i", v, u[idx]), 0.0, length[idx])
        e = v - s[:, None] * u[idx]
        lim = r + sc.MU * (np.abs(v).sum(axis=1) + r)
        return idx[np.einsum("ij,ij->i", e, e) <= lim * lim]

    x_all = np.asarray(xyz, np.float64)
    levels = len(radii) - 1
    list0 = meets(np.asarray(c0, np.float64), radii[0], np.arange(len(o)))
    t, uu = len(o), 0
    for start in range(0, len(perm), run_length):
        centres, lists, nv = np.zeros((levels + 1, 3)), [list0] + [None] * levels, 0
        for i in perm[start:start + run_length]:
            x = x_all[i]
            j = 0
            while j < nv and np.linalg.norm(x - centres[j + 1]) + d <= radii[j + 1]:
                j += 1
            for k in range(j + 1, levels + 1):
                t += len(lists[k - 1])
                lists[k] = meets(x, radii[k], lists[k - 1])
                centres[k] = x
            nv = levels
            uu += len(lists[levels])
    return t, uu


@pytest.mark.parametrize("order, q, run_length", [("hilbert", 2 / 3, 400), ("none", 0.5, 97), ("morton", 0.8, 1)])
def test_counts_are_the_algorithms(engines, order, q, run_length):
    """t (segment-sphere tests) and u (segment-disc tests) counted by the kernels
    equal a float64 replay of the algorithm on the same segments and spheres
    (up to float32 rounding of a few borderline tests)."""
    e = engines["bunny"]
    pts = surface_points(e, 400, np.random.default_rng(5))
    d = 0.003 * e.scene.diagonal
    est = e.irradiance(pts, method=METHOD, radius=d, photons=5000, count_work=True, order=order, q=q,
                       run_length=run_length)
    cache = est.estimator
    segs, _ = e.trace(photons=5000)
    perm = ordering.order_points(e.queue, pts.xyz, order)
    t, u = reference_counts(pts.xyz, perm, segs, cache.ext, cache.c0[:3], cache.radii.astype(np.float32),
                            np.float32(d), cache.run_length)
    assert abs(est.work["t"] - t) <= 1e-5 * t + 2, (est.work, t, u)
    assert abs(est.work["u"] - u) <= 1e-5 * u + 2, (est.work, t, u)


def test_counts_without_inner_spheres(engines):
    """Discs as large as the root sphere allows: no inner sphere (L = 0), so
    every segment is tested once against S_0 (t = n_R) and every disc tests
    all of them (u = n_P n_R) -- the bunny's box is closed, S_0 holds it."""
    e = engines["bunny"]
    lo, hi = (np.asarray(b, float) for b in e.scene.bounds())
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    pts = oclgi.query_points(corners, np.ones((8, 3)))
    est = e.irradiance(pts, method=METHOD, radius=0.1 * e.scene.diagonal, photons=5000, q=0.3, count_work=True)
    assert est.estimator.levels == 0 and est.work["t"] == est.stats.segments
    assert est.work["u"] == 8 * est.stats.segments


def test_total_cost_is_least_near_two_thirds(engines):
    """The issue's count test: t + u least for Q in [0.60, 0.72] over Q = 0.40 .. 0.90.

    The thesis' assumptions: 32,768 points uniform in the bunny box's volume
    (random normals), visited in Hilbert order by one traversal (one run),
    discs of radius 1e-4 x diagonal, ~1/160 of the point spacing. Counts are
    exact, so the argmin is too; it fails for a cache that does not re-use
    its spheres (order "none" puts it at 0.40) or that rebuilds the wrong
    levels. The ends must cost clearly more than the minimum, so the sweep
    does see a minimum and not a flat line.
    """
    e = engines["bunny"]
    rng = np.random.default_rng(1)
    n = 32_768
    lo, hi = np.array([-0.25, -0.05, -0.25]), np.array([0.25, 0.45, 0.25])  # inside the box
    pts = oclgi.query_points(lo + (hi - lo) * (0.05 + 0.9 * rng.random((n, 3))), rng.normal(size=(n, 3)))
    qs = np.round(np.arange(0.40, 0.901, 0.05), 2)
    cost = []
    for q in qs:
        w = e.irradiance(pts, method=METHOD, radius=1e-4 * e.scene.diagonal, photons=PHOTONS, q=float(q),
                         run_length=n, count_work=True).work
        cost.append(w["t"] + w["u"])
    cost = np.array(cost, float)
    table = ", ".join(f"{q:.2f}: {c / cost.min():.3f}" for q, c in zip(qs, cost))
    best = qs[np.argmin(cost)]
    assert 0.60 <= best <= 0.72, f"t + u least at Q = {best} (relative cost {table})"
    assert cost[0] > 1.15 * cost.min() and cost[-1] > 1.5 * cost.min(), table


# -- options ---------------------------------------------------------------------------

@pytest.mark.parametrize("bad", [{"q": 0}, {"q": 1.0}, {"q": True}, {"q": "2/3"}, {"order": "peano"},
                                 {"run_length": 0}, {"run_length": 2.5}, {"levels": 3}])
def test_bad_options(engines, points, bad):
    with pytest.raises(OclgiError):
        engines["cornell"].irradiance(points["cornell"], method=METHOD, photons=100, **bad)
