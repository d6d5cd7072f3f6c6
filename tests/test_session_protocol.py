"""One session protocol (ARCHITECTURE M5): poses of their own, estimator and
camera switches without re-tracing, closing that frees the device memory.

Every check compares a session after a change with a fresh session opened
with the new settings at the same pose, bit for bit; "nothing re-traced"
is checked on the stored segments (the same buffer, the same bytes) and
on the store's trace counter.
"""

import copy
import gc
import os

import numpy as np
import pyopencl as cl
import pytest

import oclgi
import oclgi.estimators
from analytic_scenes import translation
from test_session import _camera_engine, _moves, _points, _scene

INCREMENTAL = [m for m, c in oclgi.estimators.ESTIMATORS.items() if c.incremental]
PHOTONS = 10_000


@pytest.fixture(scope="module")
def engine(scenes_dir):
    return _camera_engine(scenes_dir)


def test_sessions_over_one_engine_are_independent(engine, rng):
    pts = _points(engine, rng, 200)
    a = oclgi.Session(engine, pts, radius=0.05, photons=PHOTONS)
    b = oclgi.Session(engine, pts, radius=0.05, photons=PHOTONS)
    start = b.accumulators()
    for m in _moves(rng, 5):
        a.move("bunny", m)
    assert not np.array_equal(a.accumulators(), start)
    # b never moved: still the first frame; a equals a fresh session at its pose
    assert np.array_equal(b.accumulators(), start)
    assert np.array_equal(a.accumulators(), oclgi.Session(a.engine, pts, radius=0.05, photons=PHOTONS).accumulators())
    b.move("bunny", translation(0.2))
    assert np.array_equal(b.accumulators(),
                          oclgi.Session(b.engine, pts, radius=0.05, photons=PHOTONS).accumulators())
    # the engine's own pose is neither's
    assert np.array_equal(engine.pose_matrix("bunny"), np.eye(4))
    assert np.array_equal(b.engine.pose_matrix("bunny"), translation(0.2).astype(np.float32))  # the records are float32
    a.close()
    b.close()


def test_engine_moves_do_not_reach_open_sessions(engine, rng):
    pts = _points(engine, rng, 100)
    s = oclgi.Session(engine, pts, radius=0.05, photons=PHOTONS)
    first = s.accumulators()
    engine.move("bunny", translation(-0.3))
    try:
        assert np.array_equal(s.accumulators(), first)
        s.move("bunny", np.eye(4))  # the session's pose was the identity all along: nothing changes
        assert np.array_equal(s.accumulators(), first)
        opened_later = oclgi.Session(engine, pts, radius=0.05, photons=PHOTONS)  # starts at the engine's pose
        assert np.array_equal(opened_later.engine.pose_matrix("bunny"), translation(-0.3).astype(np.float32))
        with pytest.raises(oclgi.OclgiError, match=r"session's move\(\)"):
            s.engine.move("bunny", np.eye(4))
    finally:
        engine.move("bunny", np.eye(4))


@pytest.mark.parametrize("camera", [False, True], ids=["points", "camera"])
def test_set_estimator_equals_fresh_without_retrace(engine, rng, camera):
    pts = None if camera else _points(engine, rng, 150)
    s = oclgi.Session(engine, pts, method="detp_disc_index", radius=0.05, photons=PHOTONS)
    for m in _moves(rng, 4):
        s.move("bunny", m)
    segments = s.store.batch.segments
    stored = s.segments()[0].tobytes()
    traces = s.store.tracer.launches
    for method in INCREMENTAL + ["detp_disc_index"]:
        s.set_estimator(method, radius=0.04)
        fresh = oclgi.Session(s.engine, pts, method=method, radius=0.04, photons=PHOTONS)
        assert np.array_equal(s.accumulators(), fresh.accumulators()), method
        assert np.array_equal(s.irradiance(), fresh.irradiance()), method
        if camera:
            assert np.array_equal(s.render()[0], fresh.render()[0]), method
        fresh.close()
    assert s.store.batch.segments is segments and s.segments()[0].tobytes() == stored
    assert s.store.tracer.launches == traces, "set_estimator traced photons"
    # still a working session: moves keep it exact under the new estimator
    s.move("bunny", translation(0.25, 0.0, -0.1))
    assert np.array_equal(s.accumulators(), oclgi.Session(s.engine, pts, method="detp_disc_index", radius=0.04,
                                                          photons=PHOTONS).accumulators())
    s.close()


def test_set_estimator_refuses_what_a_session_cannot_do(engine, rng):
    s = oclgi.Session(engine, _points(engine, rng, 20), photons=2000)
    before = s.accumulators()
    for method, words in (("photon_map", "no exact incremental update"), ("nope", "method")):
        with pytest.raises(oclgi.OclgiError, match=words):
            s.set_estimator(method)
    with pytest.raises(oclgi.OclgiError, match="radius"):
        s.set_estimator(radius=-1.0)
    assert np.array_equal(s.accumulators(), before), "a refused switch leaves the session as it was"
    with pytest.raises(oclgi.OclgiError, match="camera session"):
        s.set_camera(engine.view_camera())
    s.close()


def test_set_camera_traces_only_the_camera(engine, rng):
    s = oclgi.Session(engine, None, photons=PHOTONS, radius=0.05)
    for m in _moves(rng, 3):
        s.move("bunny", m)
    traces = s.store.tracer.launches
    cam = oclgi.Camera(position=(0.5, 1.2, 3.0), look_at=(0, 0.6, 0), fov=45.0, width=20, height=16)
    s.set_camera(cam)
    assert s.store.tracer.launches == traces
    fresh = oclgi.Session(s.engine, None, camera=cam, photons=PHOTONS, radius=0.05)
    assert s.render()[0].shape == (16, 20, 3)
    assert np.array_equal(s.render()[0], fresh.render()[0])
    s.move("bunny", translation(0.1))
    fresh.close()
    fresh = oclgi.Session(s.engine, None, camera=cam, photons=PHOTONS, radius=0.05)
    assert np.array_equal(s.render()[0], fresh.render()[0])
    s.close()
    fresh.close()


@pytest.mark.parametrize("mode", ["exact", "practical"])
def test_photon_map_camera_session(engine, rng, mode):
    """A Photon Map session over a camera's view: the view is traced again
    where a movable object may be seen; exact mode equals a fresh session at
    the pose bit for bit, practical mode renders the same pixels where
    nothing changed near them."""
    s = oclgi.PhotonMapSession(engine, None, photons=PHOTONS, k=20, mode=mode)
    first, _ = s.render()
    for m in _moves(rng, 4):
        s.move("bunny", m)
    fresh = oclgi.PhotonMapSession(s.engine, None, photons=PHOTONS, k=20, mode=mode)
    same_points = s.points.positions.tobytes() == fresh.points.positions.tobytes()
    assert same_points
    if mode == "exact":
        assert np.array_equal(s.accumulators(), fresh.accumulators())
        assert np.array_equal(s.render()[0], fresh.render()[0])
    s.move("bunny", np.eye(4))
    back, _ = s.render()
    if mode == "exact":
        assert np.array_equal(back, first)
    else:  # the practical update keeps static points' first radii: within the estimator's own noise
        assert np.median(np.abs(back - first)) <= 0.2 * np.median(first[first > 0])
    s.set_estimator(k=10)
    fresh.close()
    fresh = oclgi.PhotonMapSession(s.engine, None, photons=PHOTONS, k=10, mode=mode)
    assert np.array_equal(s.accumulators(), fresh.accumulators()) and np.array_equal(s.radii(), fresh.radii())
    with pytest.raises(oclgi.OclgiError, match="oclgi.Session"):
        s.set_estimator("detp")
    with pytest.raises(oclgi.OclgiError, match="unknown Photon Map session option"):
        s.set_estimator(radius=0.1)
    s.close()
    fresh.close()


def test_both_kinds_offer_the_protocol(engine, rng):
    pts = _points(engine, rng, 1)
    for method, kind in (("photon_map", oclgi.PhotonMapSession), ("impact", oclgi.Session),
                         ("detp_ray_map", oclgi.Session)):
        with oclgi.open_session(engine, pts, method=method, photons=1000) as s:
            assert type(s) is kind
            assert isinstance(s, oclgi.IncrementalSession)
            assert s.irradiance().shape == (1, 3)
        assert s.closed
    with pytest.raises(oclgi.OclgiError, match="method"):
        oclgi.open_session(engine, pts, method="unknown")


def _buffers(root) -> list:
    """Every OpenCL buffer reachable from a session, the engine's excepted."""
    found, seen, stack = [], set(), [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, cl.MemoryObjectHolder):
            found.append(obj)
        elif isinstance(obj, (list, tuple)):
            stack.extend(obj)
        elif isinstance(obj, dict):
            stack.extend(obj.values())
        elif isinstance(obj, oclgi.Engine):  # a session's view of the engine: its pose is the session's
            stack.append(obj.compiled.pose)
        elif type(obj).__module__.startswith("oclgi") and hasattr(obj, "__dict__") \
                and not getattr(obj, "shared_by_sessions", False):
            stack.extend(vars(obj).values())
    return found


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.parametrize("kind", ["camera", "photon_map"])
def test_close_frees_the_sessions_buffers(engine, kind):
    if kind == "camera":
        s = oclgi.Session(engine, None, photons=PHOTONS, radius=0.05)
    else:
        s = oclgi.PhotonMapSession(engine, np.array([[0, 0.01, 0, 0, 1, 0]]), photons=PHOTONS, k=20)
    s.move("bunny", translation(0.1))
    bufs = _buffers(s)
    engine_bufs = {id(v) for v in vars(engine.compiled).values() if isinstance(v, cl.MemoryObjectHolder)}
    assert len(bufs) > 10
    s.close()
    released = s.released_buffers
    assert {id(b) for b in bufs} - engine_bufs <= released, "a buffer the session owned was left"
    assert not engine_bufs & released, "the engine's buffers are shared and stay"
    for call in (s.irradiance, s.render, lambda: s.move("bunny", np.eye(4)), s.set_estimator):
        with pytest.raises(oclgi.OclgiError, match="is closed"):
            call()
    s.close()  # twice: nothing
    # the engine and other sessions are untouched
    assert oclgi.Session(engine, np.array([[0, 0.01, 0, 0, 1, 0]]), photons=1000).irradiance().shape == (1, 3)


def test_closing_sessions_gives_the_memory_back(engine):
    """Open and close sessions of 4x10^5 paths (about 190 MB of segments
    each) in turn: the process' resident memory stays near one session's,
    as it would not if closing left the buffers to the garbage collector
    (here each session's store stays referenced, as a user's variable
    may hold it)."""
    kept = []
    s = oclgi.Session(engine, np.array([[0, 0.01, 0, 0, 1, 0]]), photons=400_000, max_depth=10)
    one = s.store.nbytes
    kept.append(s.store)
    s.close()
    gc.collect()
    base = _rss()
    for _ in range(6):
        s = oclgi.Session(engine, np.array([[0, 0.01, 0, 0, 1, 0]]), photons=400_000, max_depth=10)
        kept.append(s.store)
        s.close()
    grown = _rss() - base
    assert grown < 2 * one, f"resident memory grew {grown / 2**20:.0f} MiB over 6 closed sessions of " \
                            f"{one / 2**20:.0f} MiB each"


@pytest.fixture(scope="module")
def lit_engine(scenes_dir):
    """The engine's room with a point light, lamp, that the sequences move."""
    scene = _scene(scenes_dir)
    scene.camera = oclgi.Camera(position=(0, 1, 3.94), look_at=(0, 1, 0), fov=39.3, width=16, height=16)
    scene.point_lights = [oclgi.PointLight(position=LAMP, intensity=(1.0, 1.0, 1.0), name="lamp")]
    return oclgi.Engine(scene)


LAMP = (0.0, 1.5, 0.0)


def _place_lamp(target, position) -> None:
    """Light ``lamp`` of an engine or a session moved to ``position``."""
    params = target.parameters()
    params["light.lamp.position"] = position
    params.update()


@pytest.mark.parametrize("kind", ["points", "camera", "photon_map"])
def test_any_sequence_of_changes_closes_cleanly_and_stays_exact(lit_engine, kind):
    """Random sequences of moves, light moves, photon counts and (for the
    DETP kinds) an estimator switch, then close: every step leaves a DETP
    session equal to a fresh one at its pose, light and count (bit for bit;
    a Photon Map session's practical update tends to recomputation, it is
    not equal to it), and close releases every buffer the session holds
    once, none twice (the estimator's crossing lists held the store a
    photon count replaced)."""
    engine = lit_engine
    reference = oclgi.Engine(copy.deepcopy(engine.scene))  # its lamp placed where the session's is, for the fresh sessions
    rng = np.random.default_rng(sum(map(ord, kind)))
    g = np.linspace(-0.5, 0.5, 8)
    pts = np.array([[x, 0.01, z, 0, 1, 0] for x in g for z in g])  # the floor around the bunny

    def make(on, photons, method):
        if kind == "photon_map":
            return oclgi.PhotonMapSession(on, pts, photons=photons, k=10)
        return oclgi.Session(on, None if kind == "camera" else pts, method=method, photons=photons, radius=0.05)

    for trial in range(2):
        photons, method, pose, lamp = 3_000, "detp_disc_index", np.eye(4), LAMP
        _place_lamp(reference, lamp)
        s = make(engine, photons, method)
        steps = ["move", "photons", "light", *rng.choice(["move", "photons", "method", "light"], 4)]
        for step in steps:  # the failing pair (a move, then a photon count) first
            if step == "move":
                pose = translation(float(rng.uniform(-0.2, 0.2)))
                s.move("bunny", pose)
            elif step == "photons":  # more (traced and added) or fewer (dropped)
                photons = 4_500 if photons == 3_000 else int(rng.choice([1_500, 3_000, 6_000]))
                s.set_photons(photons)
            elif step == "light":
                lamp = tuple(float(c) for c in rng.uniform((-0.4, 1.2, -0.4), (0.4, 1.7, 0.4)))
                _place_lamp(s, lamp)
                _place_lamp(reference, lamp)
            elif kind != "photon_map":
                method = "detp" if method == "detp_disc_index" else "detp_disc_index"
                s.set_estimator(method)
            fresh = make(reference, photons, method)
            if not np.array_equal(pose, np.eye(4)):
                fresh.move("bunny", pose)
            if kind != "photon_map":
                assert s.accumulators().tobytes() == fresh.accumulators().tobytes(), (trial, step)
            fresh.close()
        held = {id(b) for b in _buffers(s)}
        s.close()  # no buffer released twice (pyopencl refuses a double unref)
        assert held - {id(v) for v in vars(engine.compiled).values() if isinstance(v, cl.MemoryObjectHolder)} \
            <= s.released_buffers


def test_a_light_sessions_sequences_close_cleanly_and_stay_exact():
    """The light session's own changes in random order (the light to a
    precomputed position, reused, or anywhere else, recomputed; an estimator
    switch), then close: each step equals a fresh light session moved there
    once, bit for bit, and close releases every buffer it holds once."""
    from oclgi.incremental.light_session import LightSession
    from test_light_reuse import POSITIONS, box, points

    engine = oclgi.Engine(box(POSITIONS[0]))
    rng = np.random.default_rng(5)

    def make(method):
        return LightSession(engine, points(), light="lamp", positions=POSITIONS, photons=600, max_depth=6,
                            method=method, radius=0.12)

    s, method, at = make("detp_disc_index"), "detp_disc_index", POSITIONS[0]
    for step in ["reuse", "method", "anywhere", *rng.choice(["reuse", "anywhere", "method"], 4)]:
        if step == "reuse":
            at = POSITIONS[int(rng.integers(len(POSITIONS)))]
        elif step == "anywhere":
            at = POSITIONS[0] + rng.uniform(-0.2, 0.2, 3)
        else:
            method = "impact" if method == "detp_disc_index" else "detp_disc_index"
            s.set_estimator(method)
        if step != "method":
            assert s.move_light(at).reused == (step == "reuse")
        fresh = make(method)
        fresh.move_light(at)
        assert s.accumulators().tobytes() == fresh.accumulators().tobytes(), step
        fresh.close()
    held = {id(b) for b in _buffers(s)}
    s.close()
    assert held - {id(v) for v in vars(engine.compiled).values() if isinstance(v, cl.MemoryObjectHolder)} \
        <= s.released_buffers
