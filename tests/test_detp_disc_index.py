"""DETP with disc indexing: identical to plain DETP, and it scales as claimed.

Exactness (DESIGN.md 3, "all DETP variants select exactly the same
segments"): on the Cornell box and the bunny scene, for the three radius
fractions, with and without the emitted segments, for several leaf sizes
and work-group sizes, the fixed-point accumulators equal plain DETP's bit
for bit. Adversarial segments (grazing, ending on a disc's plane, escaping,
axis-aligned, on a rim) check that the box culling is conservative.

Cost (García 2006): with discs spread through the volume and not
overlapping much, counted segment-disc tests per segment grow like
cbrt(n_P).
"""


import numpy as np
import pytest

import oclgi
from exactness import DETP_PHOTONS, RADIUS_FRACTIONS, check_same
from oclgi.cl.layout import Segment
from oclgi.estimators import ESTIMATORS
from oclgi.photon_trace import PathBatch

METHOD = "detp_disc_index"
PHOTONS = DETP_PHOTONS  # the shared `plain` fixture's (conftest.py)




@pytest.mark.parametrize("count_emitted", [True, False])
@pytest.mark.parametrize("frac", RADIUS_FRACTIONS)
@pytest.mark.parametrize("scene", ["cornell", "bunny"])
def test_same_as_plain(engines, points, plain, scene, frac, count_emitted):
    e = engines[scene]
    est = e.irradiance(points[scene], method=METHOD, radius=frac * e.scene.diagonal, photons=PHOTONS,
                       count_emitted=count_emitted)
    check_same(plain(scene, frac, count_emitted), est, f"{scene} radius {frac} x diagonal")


@pytest.mark.parametrize("leaf_size", [1, 3, 8, 32])
@pytest.mark.parametrize("scene", ["cornell", "bunny"])
def test_leaf_sizes(engines, points, plain, scene, leaf_size):
    e = engines[scene]
    frac = RADIUS_FRACTIONS[1]
    est = e.irradiance(points[scene], method=METHOD, radius=frac * e.scene.diagonal, photons=PHOTONS,
                       leaf_size=leaf_size, count_work=True)
    check_same(plain(scene, frac, True), est, f"{scene} leaf_size {leaf_size}")
    assert est.work["u"] < est.stats.segments * len(points[scene]) / 10  # the index does cull


@pytest.mark.parametrize("local_size", [1, 7, 64])
def test_work_group_sizes(engines, points, plain, local_size):
    e = oclgi.Engine(engines["cornell"].scene, local_size=local_size)
    frac = RADIUS_FRACTIONS[2]  # large discs: many atomics on the same disc
    est = e.irradiance(points["cornell"], method=METHOD, radius=frac * e.scene.diagonal, photons=PHOTONS)
    check_same(plain("cornell", frac, True), est, f"local size {local_size}")


def test_camera_points_with_misses(engines):
    """Camera points include background pixels (zero normals): left out of
    the index, they stay zero, as in plain DETP."""
    e = engines["cornell"]
    pts = e.camera_points(width=24, height=24)
    assert (pts.tri < 0).any()
    ref = e.irradiance(pts, method="detp", radius=0.05, photons=PHOTONS)
    est = e.irradiance(pts, method=METHOD, radius=0.05, photons=PHOTONS)
    check_same(ref.accumulators, est, "camera points")


def adversarial_batch(engine, rng, n_discs=400, n_paths=12_000, max_depth=3):
    """Discs in the scene's volume and segments made to graze them: crossing
    near the rim, at angles down to the DETP cutoff, ending just before,
    on or past the plane, escaping (t_end = inf), axis-aligned (zero
    direction components), and empty slots. Returns (points, radius, batch)."""
    lo, hi = (np.asarray(b, float) for b in engine.scene.bounds())
    d = 0.02 * engine.scene.diagonal
    x = lo + rng.random((n_discs, 3)) * (hi - lo)
    n = rng.normal(size=(n_discs, 3))
    axis = rng.random(n_discs) < 0.3  # some axis-aligned normals: flat boxes
    n[axis] = np.eye(3)[rng.integers(0, 3, axis.sum())] * rng.choice([-1, 1], (axis.sum(), 1))
    n /= np.linalg.norm(n, axis=1)[:, None]
    points = oclgi.query_points(x, n)
    m = n_paths * max_depth
    k = rng.integers(0, n_discs, m)
    nk = n[k]
    u = rng.normal(size=(m, 3))
    u -= (u * nk).sum(1)[:, None] * nk
    u /= np.linalg.norm(u, axis=1)[:, None]
    target = x[k] + u * (d * rng.choice([0.0, 0.5, 1 - 1e-6, 1.0, 1 + 1e-6, 1.001], m))[:, None]
    cos = -np.where(rng.random(m) < 0.4, 10 ** rng.uniform(-6.5, -4, m), rng.random(m))
    t = rng.normal(size=(m, 3))
    t -= (t * nk).sum(1)[:, None] * nk
    t /= np.linalg.norm(t, axis=1)[:, None]
    w = t * np.sqrt(1 - cos**2)[:, None] + nk * cos[:, None]
    flat = rng.random(m) < 0.15  # a zero component: 0 * inf in the slab tests
    w[flat, rng.integers(0, 3, flat.sum())] = 0.0
    w /= np.linalg.norm(w, axis=1)[:, None]
    back = rng.uniform(0.0, 0.5, m) * engine.scene.diagonal
    segs = np.zeros(m, Segment)
    segs["org"] = target - w * back[:, None]
    segs["dir"] = w
    t_end = back * rng.choice([1 - 1e-6, 1.0, 1 + 1e-6, 0.5, 2.0], m)
    t_end[rng.random(m) < 0.1] = np.inf
    segs["t_end"] = t_end
    segs["power"] = rng.uniform(0.1, 1.0, (m, 3))
    segs["path"] = np.repeat(np.arange(n_paths), max_depth)
    ends = rng.integers(1, max_depth + 1, n_paths)  # empty slots past each path's end
    empty = (np.arange(m) % max_depth) >= np.repeat(ends, max_depth)
    segs[empty] = np.zeros(1, Segment)
    import pyopencl as cl

    buf = cl.Buffer(engine.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=segs)
    lens = cl.Buffer(engine.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=ends.astype(np.int32))
    return points, d, PathBatch(buf, lens, 0, n_paths, max_depth)


def run_on_batch(engine, method, points, radius, batch, count_emitted, **options):
    est = ESTIMATORS[method](engine.queue, engine.compiled, points, radius=radius, count_emitted=count_emitted,
                             **options)
    scale = 2.0**24
    est.accumulate(batch, scale)
    est.accumulate(batch, scale)  # batches add up
    return est.accumulators()


@pytest.mark.parametrize("count_emitted", [True, False])
def test_adversarial_segments(engines, count_emitted):
    e = engines["cornell"]
    pts, d, batch = adversarial_batch(e, np.random.default_rng(7))
    ref = run_on_batch(e, "detp", pts, d, batch, count_emitted)
    assert (ref != 0).any(axis=1).sum() > 0.5 * len(pts)
    for leaf_size in (1, 8):
        got = run_on_batch(e, METHOD, pts, d, batch, count_emitted, leaf_size=leaf_size)
        assert np.array_equal(got, ref), f"leaf_size {leaf_size}: {(got != ref).any(axis=1).sum()} discs differ"


def test_u_grows_like_cube_root_of_points(engines):
    """Counted u per segment ~ n_P^(1/3) (García 2006's T = u n_R cbrt(n_P)).

    Discs fill the Cornell box's volume (uniform centres, random normals),
    their radius half the mean spacing (V / n_P)^(1/3), so they do not
    overlap much; n_P from 10^3 to 10^5 (two decades, five sizes), the same
    photons. The least-squares slope of log(u / n_R) against log(n_P) must
    be 1/3 within 0.07: a walk that tested every disc would give 1, one that
    culled nothing per leaf but visited leaves along the segment 1/3, one
    that found nothing 0.
    """
    e = engines["cornell"]
    lo, hi = (np.asarray(b, float) for b in e.scene.bounds())
    volume = np.prod(hi - lo)
    rng = np.random.default_rng(11)
    sizes = np.round(np.logspace(3, 5, 5)).astype(int)
    per_segment = []
    for n in sizes:
        pts = oclgi.query_points(lo + rng.random((n, 3)) * (hi - lo), rng.normal(size=(n, 3)))
        radius = 0.5 * (volume / n) ** (1 / 3)
        est = e.irradiance(pts, method=METHOD, radius=radius, photons=10_000, count_work=True)
        per_segment.append(est.work["u"] / est.stats.segments)
    slope = np.polyfit(np.log(sizes), np.log(per_segment), 1)[0]
    assert abs(slope - 1 / 3) <= 0.07, f"u / n_R = {np.round(per_segment, 1).tolist()}: exponent {slope:.3f}"


@pytest.mark.parametrize("bad", [{"leaf_size": 0}, {"leaf_size": 2.5}, {"leaf_size": True}, {"piece": 0.1}])
def test_bad_options(engines, points, bad):
    from oclgi.errors import OclgiError

    with pytest.raises(OclgiError):
        engines["cornell"].irradiance(points["cornell"], method=METHOD, photons=100, **bad)


def test_replace_points(engines):
    """Points replaced in place (a session's dynamic points) are indexed
    again: the sums equal a fresh estimator's over the new points."""
    from oclgi.queries import QueryPoints

    e = engines["cornell"]
    pts, d, batch = adversarial_batch(e, np.random.default_rng(9))
    est = ESTIMATORS[METHOD](e.queue, e.compiled, pts, radius=d)
    idx = np.arange(0, len(pts), 3)
    moved, _, _ = adversarial_batch(e, np.random.default_rng(10))  # other discs
    new = QueryPoints(moved.positions[idx], moved.normals[idx], moved.barys[idx])
    est.replace_points(idx, new)
    est.accumulate(batch, 2.0**24)
    ref = ESTIMATORS["detp"](e.queue, e.compiled, est.points, radius=d)
    ref.accumulate(batch, 2.0**24)
    assert ref.accumulators()[idx].any()
    assert np.array_equal(est.accumulators(), ref.accumulators())
