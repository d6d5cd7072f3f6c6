"""Final gathering in sessions (oclgi/estimators/final_gather.py's
``regather``, oclgi/incremental/session.py): after every move a gathered
session equals a fresh session at that pose bit for bit, for every DETP
variant, with points on the floor, the walls
and the moved bunny itself (its dynamic points gather too); without the
regather the same moves leave it wrong (the test can fail); a session with
no point on a movable object equals the plain run; a camera session
gathers exactly too (light animations: tests/test_final_gather.py)."""

import numpy as np
import pytest

import oclgi
from oclgi.errors import OclgiError
from oclgi.estimators.final_gather import FinalGather
from oclgi.queries import QueryPoints

VARIANTS = ["detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache"]
KW = dict(photons=6_000, radius=0.12, direct="exact", direct_samples=4, gather=6)


@pytest.fixture(scope="module")
def engine(scenes_dir):
    return oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_bunny.toml"))


def points(engine, on_bunny=True):
    """Floor and back-wall points, and (``on_bunny``) points at the centres
    of 12 of the bunny's triangles, carrying those triangles: they move with
    the bunny (the session's dynamic layer)."""
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(-0.9, 0.9, 30), np.zeros(30), rng.uniform(-0.9, 0.9, 30),
                             np.zeros(30), np.ones(30), np.zeros(30)])
    wall = np.column_stack([rng.uniform(-0.9, 0.9, 10), rng.uniform(0.1, 1.8, 10), np.full(10, -1.0),
                            np.zeros(10), np.zeros(10), np.ones(10)])
    a = np.concatenate([floor, wall])
    tri = np.full(len(a), -1)
    if on_bunny:
        scene = engine.scene
        first, end = scene.object_ranges()[scene.object_id("bunny")]
        ids = np.arange(first, end, (end - first) // 12)[:12]
        p = scene.vertices[scene.faces[ids]]  # the bunny as loaded, where the engine has it
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        a = np.concatenate([a, np.column_stack([p.mean(axis=1), n / np.linalg.norm(n, axis=1, keepdims=True)])])
        tri = np.concatenate([tri, ids])
    return QueryPoints(np.column_stack([a[:, :3], tri]), a[:, 3:], np.full((len(a), 2), 1 / 3))


def moves(engine, n):
    rng = np.random.default_rng(7)
    m0 = engine.pose_matrix("bunny")
    out = []
    for _ in range(n):
        a = rng.uniform(0, 2 * np.pi)
        r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        m = m0.copy()
        m[:3, :3] = r @ m0[:3, :3]
        m[0, 3] += rng.uniform(-0.5, 0.4)
        m[2, 3] += rng.uniform(-0.6, 0.3)
        out.append(m)
    return out


def fresh(engine, pts, matrix, **kw):
    """A fresh session at the pose ``matrix``, over ``pts`` where they are
    at that pose (a moved session's ``points``: the bunny's have moved)."""
    e = engine.posed()
    e.place("bunny", matrix)
    with oclgi.Session(e, pts, **kw) as s:
        return s.irradiance()


@pytest.mark.parametrize("method", VARIANTS)
def test_moves_equal_a_fresh_session(engine, method):
    pts = points(engine)
    kw = dict(KW, method=method)
    changed = []
    with oclgi.Session(engine, pts, **kw) as s:
        for i, m in enumerate(moves(engine, 20)):
            st = s.move("bunny", m)
            changed.append(st.rays_changed)
            assert "gather" in st.seconds
            if i % 4 == 3:  # every fourth move, and the last
                assert np.array_equal(s.irradiance(), fresh(engine, s.points, m, **kw)), (method, i)
    assert min(changed) > 0 and max(changed) < len(pts) * KW["gather"], changed


def test_without_the_regather_a_move_leaves_it_wrong(engine, monkeypatch):
    pts = points(engine, on_bunny=False)
    kw = dict(KW, method="detp_disc_index")
    m = moves(engine, 1)[0]
    monkeypatch.setattr(FinalGather, "regather", lambda self, batch: 0)
    with oclgi.Session(engine, pts, **kw) as s:
        s.move("bunny", m)
        stale = s.irradiance()
    monkeypatch.undo()
    assert not np.array_equal(stale, fresh(engine, pts, m, **kw))


def test_a_session_without_dynamic_points_equals_the_plain_run(engine):
    pts = points(engine, on_bunny=False)
    kw = dict(KW, method="detp_disc_index")
    with oclgi.Session(engine, pts, **kw) as s:
        got = s.irradiance()
    assert np.array_equal(got, engine.irradiance(pts, **kw).irradiance)


def test_a_camera_session_gathers_exactly(engine):
    """A camera session: its static layer's rays are traced again after
    each move (as given points'), the pixels on the bunny gather afresh;
    after 8 moves it equals a fresh camera session at each second pose."""
    cam = oclgi.Camera(position=(0.0, 1.0, 3.94), look_at=(0.0, 0.6, 0.0), fov=39.3, width=12, height=10)
    kw = dict(KW, method="detp_disc_index", camera=cam)
    stats = []
    with oclgi.Session(engine, None, **kw) as s:
        for i, m in enumerate(moves(engine, 8)):
            stats.append(s.move("bunny", m))
            if i % 2 == 1:
                e = engine.posed()
                e.place("bunny", m)
                with oclgi.Session(e, None, **kw) as f:
                    assert np.array_equal(s.irradiance(), f.irradiance()), i
    assert max(st.points for st in stats) > 0 and max(st.rays_changed for st in stats) > 0


def test_default_light_samples_are_the_whole_requests(engine):
    """The direct light's default sample count is taken from the whole
    request (photons and every query point): a session whose bunny points
    are a layer of their own equals the plain run over all the points at
    the same pose, bit for bit; the count grows with the photons and falls
    with the points."""
    from oclgi.estimators.detp_direct import default_samples

    pts = points(engine)
    kw = dict(method="detp_disc_index", photons=50_000, radius=0.12, direct="exact")
    m = moves(engine, 1)[0]
    with oclgi.Session(engine, pts, **kw) as s:
        s.move("bunny", m)
        e = engine.posed()
        e.place("bunny", m)
        assert len(s.dyn_index) == 12
        assert np.array_equal(s.irradiance(), e.irradiance(s.points, **kw).irradiance)
    assert default_samples(50_000, len(pts)) < default_samples(50_000, 12)  # the bunny's layer alone
    assert default_samples(10**7, 256) > default_samples(10**6, 256) > default_samples(10**6, 10**6) == 16
