"""Photon Map sessions (oclgi/incremental/photon_map_session.py): the map, the two modes, the drift.

After a sequence of moves of the bunny in the Cornell box:

1. the map's impacts equal those of a fresh trace at the new pose, bit for
   bit and in the same (canonical) order;
2. points on the moving object moved with it, and their sums and radii
   equal a recomputation's bit for bit (both modes);
3. practical mode: every other point's sum is exactly the fixed-radius sum,
   with its first-frame r_k, over the current impacts (checked against a
   numpy brute force), so it depends on the pose only: back at the first
   pose every estimate is the first frame's again, bit for bit;
4. exact mode: every sum and radius equals a recomputation, bit for bit;
5. the practical mode's drift from recomputation stays below the
   estimator's own noise (two seeds' difference);
6. bad input fails with one clear line.
"""

import numpy as np
import pyopencl as cl
import pytest

import oclgi
from oclgi.cl.constants import FIXED_ONE
from oclgi.errors import OclgiError
from test_session import _moves, _points, _scene

K = 30
PHOTONS = 20_000


@pytest.fixture(scope="module")
def engine(scenes_dir):
    return oclgi.Engine(_scene(scenes_dir))


def _bunny_vertices(engine, n=60):
    """Some of the bunny's vertices (their triangle is the bunny's: attached to it)."""
    v = engine.vertex_points()
    a, b = engine.scene.object_ranges()[engine.scene.object_id("bunny")]
    ids = np.nonzero((v.tri >= a) & (v.tri < b))[0][::97][:n]
    return oclgi.QueryPoints(v.positions[ids], v.normals[ids], v.barys[ids])


@pytest.fixture(scope="module")
def points(engine):
    """300 points on the room's surfaces, then 60 on the bunny."""
    room = _points(engine, np.random.default_rng(7))
    bunny = _bunny_vertices(engine)
    cat = lambda f: np.concatenate([getattr(room, f), getattr(bunny, f)])  # noqa: E731
    return oclgi.QueryPoints(cat("positions"), cat("normals"), cat("barys")), len(room)


def _slide(n, step=0.02):
    """Small moves of the bunny across the floor, turning a little: frames of an animation."""
    out = []
    for i in range(1, n + 1):
        a = 0.05 * i
        m = np.eye(4)
        m[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
        m[:3, 3] = [-step * i, 0, -0.5 * step * i]
        out.append(m)
    return out


def _session(engine, pts, mode="practical", **kw):
    engine.move("bunny", np.eye(4))
    return oclgi.PhotonMapSession(engine, pts, photons=PHOTONS, k=K, mode=mode, **kw)


def _r2(session):
    """r_k^2 as the search wrote it (float32)."""
    out = np.empty(len(session.points), np.float32)
    cl.enqueue_copy(session.queue, out, session.map.r2)
    return out


def _quantised(power):
    """convert_long3_rte(power * 2^FIXED_BITS) in float32, as the kernels quantise."""
    return np.rint(power.astype(np.float32) * np.float32(FIXED_ONE)).astype(np.int64)


def _fixed_radius_sums(pos, dirs, pw, qp, qn, r2):
    """Sum of the quantised powers of the front-side impacts with d2 < r2, per point (float32 as the kernels)."""
    qpow = _quantised(pw)
    out = np.zeros((len(qp), 3), np.int64)
    for i, (q, n, r) in enumerate(zip(qp, qn, r2)):
        d = pos - q
        d2 = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]
        wn = (dirs[:, 0] * n[0] + dirs[:, 1] * n[1]) + dirs[:, 2] * n[2]
        out[i] = qpow[(d2 < r) & (wn < np.float32(-1e-6))].sum(axis=0)
    return out


def test_practical_update(engine, points):
    pts, n_room = points
    session = _session(engine, pts)
    first = session.accumulators(), session.radii(), session.irradiance()
    r2_first = _r2(session)
    assert np.isfinite(first[1]).all() and first[0][:, 0].min() > 0, "every point must see k impacts"
    moves = _slide(12)
    for m in moves:
        stats = session.move("bunny", m)
        assert stats.paths > 0 and stats.points == len(pts) - n_room  # only the bunny's points searched again
    fresh = session.recompute()
    est = fresh.estimator

    # 1. the map is a fresh trace's, bit for bit
    for got, want in zip(session.impacts(), est.impacts()):
        assert got.tobytes() == want.tobytes()

    # 2. the bunny's points moved with it and equal a recomputation
    bunny = slice(n_room, None)
    want_pos = pts.positions[bunny, :3].astype(np.float64) @ moves[-1][:3, :3].T + moves[-1][:3, 3]
    assert np.allclose(session.points.positions[bunny, :3], want_pos, atol=1e-6)
    assert np.array_equal(session.accumulators()[bunny], fresh.accumulators[bunny])
    assert np.array_equal(session.radii()[bunny], est.radii()[bunny])

    # 3. room points: the fixed-radius sums over the current impacts, with the first radii
    acc = session.accumulators()
    assert np.array_equal(session.radii()[:n_room], first[1][:n_room])
    pos, dirs, pw = est.impacts()
    brute = _fixed_radius_sums(pos, dirs, pw, pts.positions[:n_room, :3], pts.normals[:n_room, :3], r2_first[:n_room])
    assert np.array_equal(acc[:n_room], brute)
    changed = (acc[:n_room] != first[0][:n_room]).any(axis=1)
    assert changed.sum() > 10, "the moves must change some room points' sums"
    differ = (acc[:n_room] != fresh.accumulators[:n_room]).any(axis=1)
    assert differ.sum() > 10, "practical is not recomputation: some room points must differ"

    # back at the first pose: the first frame, bit for bit (and so the recomputation there)
    session.move("bunny", np.eye(4))
    assert np.array_equal(session.accumulators(), first[0]) and np.array_equal(session.radii(), first[1])
    assert np.array_equal(session.irradiance(), first[2])
    assert session.points.positions.tobytes() == pts.positions.tobytes()  # w: tri bits, NaN for -1


def test_exact_equals_recomputation(engine, points):
    pts, n_room = points
    session = _session(engine, pts, mode="exact")
    searched = 0
    for m in _moves(np.random.default_rng(3), 6) + _slide(3):
        searched += session.move("bunny", m).points - (len(pts) - n_room)
        fresh = session.recompute()
        assert np.array_equal(session.accumulators(), fresh.accumulators)
        assert np.array_equal(session.radii(), fresh.estimator.radii())
        assert np.array_equal(session.irradiance(), fresh.irradiance)
    assert 0 < searched < 9 * n_room, "exact mode searches the points whose ball changed, not all"


def test_practical_drift_below_noise(engine, points):
    """After 30 frames of an animation the practical estimate's RMS error
    against recomputation is below one estimate's noise (two seeds'
    difference over sqrt 2), measured here, not assumed. Measured in
    bench/photon_map_drift.py (10^5 photons, k = 50, 80 frames): drift
    0.020 to 0.031, noise 0.15, flat over the frames; here (2x10^4
    photons, k = 30) 0.025 against 0.18. The bound is loose on
    purpose (a shared machine, another scene and seed must not fail it),
    yet an update that loses its subtract pass, or adds each impact
    twice, exceeds it: every changed impact then moves a sum by a whole
    photon, 1/(k-1) of the estimate, for good."""
    pts, n_room = points
    session = _session(engine, pts)
    for m in _slide(30):
        session.move("bunny", m)
    e = session.irradiance()[:n_room].sum(axis=1)
    f = session.recompute().irradiance[:n_room].sum(axis=1)
    g = session.recompute(seed=99).irradiance[:n_room].sum(axis=1)
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    drift, noise = rms(e - f) / rms(f), rms(g - f) / np.sqrt(2) / rms(f)
    assert 0.05 < noise < 0.5, noise  # k = 30: about 1/sqrt(28) = 0.19
    print(f"drift {drift:.4f}, noise {noise:.4f}")
    assert 0 < drift < noise, (drift, noise)


def test_bad_input(engine, points):
    pts, _ = points
    with pytest.raises(OclgiError, match="mode must be one of 'practical', 'exact'") as info:
        oclgi.PhotonMapSession(engine, pts, photons=1000, mode="fast")
    assert "\n" not in str(info.value)
    with pytest.raises(OclgiError, match="k must be an integer"):
        oclgi.PhotonMapSession(engine, pts, photons=1000, k=0)
    session = _session(engine, pts)
    with pytest.raises(OclgiError, match="no movable object named 'static'") as info:
        session.move("static", np.eye(4))
    assert "\n" not in str(info.value)
    with pytest.raises(OclgiError, match="singular"):
        session.move("bunny", np.diag([1.0, 1.0, 0.0, 1.0]))
