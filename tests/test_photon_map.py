"""Photon Maps (oclgi/estimators/photon_map.py): the neighbours, the bias, the bits.

1. The k nearest front-side impacts equal a brute force over the same
   float32 numbers, ties included (rank by (d2, id)), on random data
   (continuous and on a lattice, where distances tie) and on real impacts
   of the Cornell box; and equal scipy's cKDTree up to the order of
   float64 near-ties.
2. Bias as theory says (point light over a black plane, all photons of
   equal power): the k estimator over the k-1 one is exactly k / (k-1) at
   every point; over many points the k-1 one is unbiased, the k one
   over-estimates by k / (k-1), and the relative spread is 1 / sqrt(k-2)
   (pi r_k^2 lambda ~ Gamma(k, 1) for a uniform density); with 10^6
   photons and a large k the k-1 estimate is within a few % at every
   interior point. The furnace box too.
3. Gathering: impacts are the segment ends in (path, bounce) order;
   count_emitted=False drops bounce 0; results do not depend on the batch
   size or work-group size; bad options and too many impacts fail
   with a clear error.
"""

import math

import numpy as np
import pytest
from analytic_scenes import box, exact, face_points, ring_points
from exactness import surface_points
from scipy.spatial import cKDTree

import oclgi
from oclgi.cl.constants import FIXED_ONE, FRONT_COS_EPS
from oclgi.errors import OclgiError
from oclgi.estimators import photon_map as pm
from oclgi.accel.point_index import KnnIndex

EPS = np.float32(FRONT_COS_EPS)  # the kernels' front-side rule


def brute_knn(pos, dirs, qp, qn, k, front_only=True):
    """The k smallest (d2, id) per query, d2 in float32 as the kernel sums it."""
    pos = np.asarray(pos, np.float32)
    dirs = np.asarray(dirs, np.float32)
    ids = np.full((len(qp), k), -1, np.int64)
    d2s = np.full((len(qp), k), np.inf, np.float32)
    for i, (q, n) in enumerate(zip(np.asarray(qp, np.float32), np.asarray(qn, np.float32))):
        d = pos - q
        d2 = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]
        cand = np.arange(len(pos))
        if not n.any():
            continue
        if front_only:
            wn = (dirs[:, 0] * n[0] + dirs[:, 1] * n[1]) + dirs[:, 2] * n[2]
            cand = cand[wn < -EPS]
        best = cand[np.lexsort((cand, d2[cand]))[:k]]
        ids[i, :len(best)] = best
        d2s[i, :len(best)] = d2[best]
    return ids, d2s


def assert_same_as_kdtree(ids, d2, pos, qp, k):
    """Same neighbour sets as cKDTree, except where float64 distances leave
    the k-th and (k+1)-th within rounding; there the distances agree."""
    dist, idx = cKDTree(pos.astype(np.float64)).query(qp.astype(np.float64), k + 1)
    np.testing.assert_allclose(np.sqrt(d2), dist[:, :k], rtol=1e-5, atol=1e-7)
    clear = dist[:, k] - dist[:, k - 1] > 1e-5 * dist[:, k] + 1e-7
    assert clear.mean() > 0.9
    for i in np.nonzero(clear)[0]:
        assert set(ids[i]) == set(idx[i, :k]), i


@pytest.fixture(scope="module")
def queue(cl_env):
    return cl_env[1]


def test_neighbours_random(queue):
    rng = np.random.default_rng(5)
    n, m, k = 20_000, 200, 24
    pos = rng.random((n, 3)).astype(np.float32)
    pos[: n // 2, 2] = 0.5  # a plane of points inside a volume: two densities
    dirs = rng.normal(size=(n, 3)).astype(np.float32)
    qp = rng.random((m, 3)).astype(np.float32)
    qn = rng.normal(size=(m, 3)).astype(np.float32)
    knn = KnnIndex(queue, pos, dirs)
    for front in (True, False):
        ids, d2 = knn.neighbours(qp, qn, k, front_only=front)
        ref_ids, ref_d2 = brute_knn(pos, dirs, qp, qn, k, front)
        assert np.array_equal(ids, ref_ids) and np.array_equal(d2, ref_d2)
    assert_same_as_kdtree(*knn.neighbours(qp, qn, k, front_only=False), pos, qp, k)


def test_neighbours_ties_on_a_lattice(queue):
    """Points on an integer lattice, each repeated: distances tie everywhere,
    and the smaller ids must win."""
    rng = np.random.default_rng(8)
    g = np.stack(np.meshgrid(*[np.arange(12)] * 3, indexing="ij"), -1).reshape(-1, 3)
    pos = np.repeat(g, 2, axis=0).astype(np.float32)
    pos = pos[rng.permutation(len(pos))]
    dirs = np.tile(np.float32([0, 0, -1]), (len(pos), 1))
    qp = (rng.integers(0, 24, (150, 3)) / 2.0).astype(np.float32)  # on points, edges and centres
    qn = np.tile(np.float32([0, 0, 1]), (len(qp), 1))
    ids, d2 = KnnIndex(queue, pos, dirs).neighbours(qp, qn, 33)
    ref_ids, ref_d2 = brute_knn(pos, dirs, qp, qn, 33)
    assert np.array_equal(ids, ref_ids) and np.array_equal(d2, ref_d2)


def test_neighbours_far_queries_duplicates_and_back_sides(queue):
    """Queries far outside the impacts' box, all impacts at one point, and
    points that see no impact on their front side (ids -1, d2 inf)."""
    rng = np.random.default_rng(2)
    pos = (rng.random((3000, 3)) * [1, 1, 0] + [3, 4, 5]).astype(np.float32)  # a flat square
    dirs = np.tile(np.float32([0, 0, -1]), (len(pos), 1))
    qp = np.concatenate([rng.random((40, 3)) * 20 - 10, rng.random((40, 3)) * [1, 1, 0.01] + [3, 4, 5]])
    qp = qp.astype(np.float32)
    qn = np.tile(np.float32([0, 0, 1]), (len(qp), 1))
    qn[::3] = [0, 0, -1]  # these face away from every impact
    for p in (pos, np.full_like(pos[:300], 1.5)):
        d = dirs[: len(p)]
        ids, d2 = KnnIndex(queue, p, d).neighbours(qp, qn, 20)
        ref_ids, ref_d2 = brute_knn(p, d, qp, qn, 20)
        assert np.array_equal(ids, ref_ids) and np.array_equal(d2, ref_d2)
        assert (ids[::3] == -1).all() and np.isinf(d2[::3]).all()


def test_neighbours_cornell_impacts(cornell):
    pts = surface_points(cornell, 300, np.random.default_rng(3))
    k = 40
    est = cornell.irradiance(pts, method="photon_map", photons=40_000, k=k)
    pmap = est.estimator
    pos, dirs, power = pmap.impacts()
    ids, d2 = pmap.neighbours()
    qp, qn = pts.positions[:, :3], pts.normals[:, :3]
    ref_ids, ref_d2 = brute_knn(pos, dirs, qp, qn, k)
    assert np.array_equal(ids, ref_ids) and np.array_equal(d2, ref_d2)
    # cKDTree per normal (the front-side subset depends on the normal only)
    for nrm in np.unique(qn, axis=0):
        rows = np.nonzero((qn == nrm).all(axis=1))[0]
        front = np.nonzero((dirs[:, 0] * nrm[0] + dirs[:, 1] * nrm[1]) + dirs[:, 2] * nrm[2] < -EPS)[0]
        # ids are canonical; the tree numbers the front subset
        assert_same_as_kdtree(np.searchsorted(front, ids[rows]), d2[rows], pos[front], qp[rows], k)
    # the estimate is built from exactly these neighbours
    # impacts carry power in units of the largest photon power: 2^24 fixed-point units
    q = np.rint(power.astype(np.float32) * np.float32(FIXED_ONE)).astype(np.int64)
    expect = q[ref_ids].sum(axis=1) - q[ref_ids[:, -1]]
    assert np.array_equal(est.accumulators, expect)
    r2 = ref_d2[:, -1].astype(np.float64)
    np.testing.assert_allclose(est.irradiance, expect / est.scale / (math.pi * r2[:, None]), rtol=1e-5)


def test_impacts_are_segment_ends(cornell):
    """Impacts = ends of the segments that hit, in (path, bounce) order;
    count_emitted=False drops bounce 0."""
    photons, depth = 3000, cornell.scene.settings.max_depth
    seg, _ = cornell.trace(photons=photons)
    pt = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
    for emitted in (True, False):
        est = cornell.irradiance(pt, method="photon_map", photons=photons, k=2, count_emitted=emitted)
        pos, dirs, power = est.estimator.impacts()
        keep = seg["tri"] >= 0
        if not emitted:
            keep &= np.arange(len(seg)) % depth != 0
        s = seg[keep]
        end = s["org"] + s["t_end"][:, None] * s["dir"]
        assert np.array_equal(pos, end.astype(np.float32)) and np.array_equal(dirs, s["dir"])
        assert np.array_equal(power * cornell.photon_watts(photons), s["power"])  # impacts in device units


def _run_bits(engine, pts, **kw):
    return engine.irradiance(pts, method="photon_map", photons=30_000, k=30, **kw).accumulators


def test_bits_do_not_depend_on_batches_or_groups(scenes_dir):
    scene = oclgi.load_file(scenes_dir / "cornell_box.toml")
    e = oclgi.Engine(scene)
    pts = e.camera_points(width=24, height=24)
    ref = _run_bits(e, pts)
    assert ref.any()
    small = oclgi.Engine(scene, batch_bytes=16 * 48 * 1000)  # 1,000 paths per batch
    for engine in [e, small, *[oclgi.Engine(scene, local_size=ls) for ls in (1, 7, 128)]]:
        assert np.array_equal(_run_bits(engine, pts), ref), engine.local_size


def test_k_over_k_minus_1_on_the_plane(plane):
    """Equal photon powers: sum_k / sum_{k-1} = k / (k-1) exactly, same r_k;
    over 4,000 points the k-1 estimate is unbiased and the k one is high by
    k / (k-1); the spread is 1 / sqrt(k - 2)."""
    rng = np.random.default_rng(0)
    n, k = 4000, 10
    r, a = np.sqrt(rng.random(n)), rng.random(n) * 2 * np.pi
    p = np.stack([r * np.cos(a), np.zeros(n), r * np.sin(a)], 1)
    pts = np.hstack([p, np.tile([0.0, 1.0, 0.0], (n, 1))])
    lo = plane.irradiance(pts, method="photon_map", photons=1_000_000, k=k)
    hi = plane.irradiance(pts, method="photon_map", photons=1_000_000, k=k, estimator="k")
    assert np.array_equal(hi.accumulators * (k - 1), lo.accumulators * k)
    np.testing.assert_allclose(hi.irradiance / lo.irradiance, k / (k - 1), rtol=1e-6)
    rel = lo.irradiance[:, 0] / exact(p[:, 0], p[:, 2])
    sigma = 1 / math.sqrt(k - 2)
    assert abs(rel.mean() - 1) < 4 * sigma / math.sqrt(n)  # 2.2%
    assert rel.std() == pytest.approx(sigma, rel=0.1)
    rel_hi = hi.irradiance[:, 0] / exact(p[:, 0], p[:, 2])
    assert abs(rel_hi.mean() - k / (k - 1)) < 4 * sigma / math.sqrt(n)


def test_point_light_plane_accuracy(plane):
    """k-1, k = 2048, 10^6 photons: every interior point within 8% (3.6
    sigma of the 1 / sqrt(k-2) = 2.2% noise) and the mean within 1%."""
    p, pts = ring_points()
    est = plane.irradiance(pts, method="photon_map", photons=1_000_000, k=2048)
    rel = est.irradiance[:, 0] / exact(p[:, 0], p[:, 2]) - 1
    assert np.abs(rel).max() < 0.08 and abs(rel.mean()) < 0.01
    assert np.array_equal(est.accumulators[:, 0], est.accumulators[:, 2])


def test_furnace_box(rng):
    """All bounces: within 5% of pi Le / (1 - rho) at points 0.15 from the
    edges (k = 4096: r_k ~ 0.06, noise 1.6%)."""
    engine = oclgi.Engine(box(rho=0.5, le=1.0))
    p, n = face_points(rng)
    est = engine.irradiance(np.hstack([p, n]), method="photon_map", k=4096)
    expected = math.pi / (1 - 0.5)
    assert np.abs(est.irradiance / expected - 1).max() < 0.05
    assert abs(est.irradiance.mean() / expected - 1) < 0.01


def test_options_and_errors(cornell, monkeypatch):
    pt = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
    for bad in ({"k": 0}, {"k": pm.MAX_K + 1}, {"k": 2.5}, {"k": 1}, {"estimator": "k+1"},
                {"index": "grid"}, {"front_only": "yes"}, {"leaf_size": 0}):
        with pytest.raises(OclgiError, match="photon_map"):
            cornell.irradiance(pt, method="photon_map", photons=1000, **bad)
    with pytest.raises(OclgiError, match="only .* impacts"):
        cornell.irradiance(pt, method="photon_map", photons=3, k=100)
    monkeypatch.setattr(pm, "max_impacts", lambda device: 5000)
    with pytest.raises(OclgiError, match="more than 5,000 impacts"):
        cornell.irradiance(pt, method="photon_map", photons=20_000)
    # k = 1 is fine for the k estimator; work counts come from the search
    e = cornell.irradiance(pt, method="photon_map", photons=1000, k=1, estimator="k", count_work=True)
    assert e.irradiance.shape == (1, 3) and e.work["u"] >= 1 and e.work["nodes"] >= 1
