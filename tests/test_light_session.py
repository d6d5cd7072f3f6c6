"""A light session (oclgi/incremental/light_session.py): the light dragged
among an animation's positions by path reuse, anywhere else by recomputation,
and it says which; the session protocol where it applies."""

import numpy as np
import pytest

import oclgi
from oclgi.incremental.light_session import LightSession
from oclgi.tracing.light_reuse import LightReuse
from test_light_reuse import AXES, POSITIONS, RADIUS, box, points

N = 1000


@pytest.mark.parametrize("spot", [False, True], ids=["point", "spot"])
def test_precomputed_positions_by_reuse_others_recomputed(spot):
    axes = AXES if spot else None
    engine = oclgi.Engine(box(POSITIONS[0], spot=AXES[0] if spot else None))
    s = LightSession(engine, points(), light="lamp", positions=POSITIONS, directions=axes, photons=N, seed=3,
                     max_depth=6, radius=RADIUS)
    reuse = LightReuse(engine, "lamp", POSITIONS, axes, photons=N, seed=3, max_depth=6)
    frames = reuse.frames_irradiance(points(), radius=RADIUS)
    for j in (2, 0, 3, 1):
        done = s.move_light(POSITIONS[j], None if axes is None else AXES[j])
        assert done.reused and done.frame == j and done.paths_traced == 0
        assert np.array_equal(s.accumulators(), frames[j].accumulators)
    # a free move: an ordinary run with the light there, equal to a fresh engine's
    free = (0.1, 1.4, 0.1)
    done = s.move_light(free, (0.0, -1.0, 0.1) if spot else None)
    assert not done.reused and done.frame is None and done.paths_traced == N
    there = oclgi.Engine(box(free, spot=(0.0, -1.0, 0.1) if spot else None))
    fresh = there.irradiance(points(), photons=N, seed=3, max_depth=6, radius=RADIUS)
    assert np.array_equal(s.accumulators(), fresh.accumulators)
    # back on the path: reuse again
    assert s.move_light(POSITIONS[1], None if axes is None else AXES[1]).reused
    assert np.array_equal(s.accumulators(), frames[1].accumulators)
    s.close()


def test_light_session_protocol():
    engine = oclgi.Engine(box(POSITIONS[0]))
    cam = oclgi.Camera(position=(0, 1, 3.94), look_at=(0, 1, 0), fov=39.3, width=16, height=16)
    s = LightSession(engine, None, light="lamp", positions=POSITIONS, photons=N, max_depth=6, radius=RADIUS,
                     camera=cam)
    assert isinstance(s, oclgi.IncrementalSession)
    first, _ = s.render()
    assert first.shape == (16, 16, 3) and first.max() > 0
    s.move_light(POSITIONS[2])
    assert not np.array_equal(s.render()[0], first)
    s.set_estimator("impact")
    reuse = LightReuse(engine, "lamp", POSITIONS, photons=N, max_depth=6)
    want = reuse.estimate(2, reuse.estimator(s.points, "impact"))
    assert np.array_equal(s.accumulators(), want.accumulators)
    s.set_camera(oclgi.Camera(position=(0.3, 1.2, 3.0), look_at=(0, 0.8, 0), fov=45.0, width=12, height=10))
    assert s.render()[0].shape == (10, 12, 3)
    with pytest.raises(oclgi.OclgiError, match="objects do not move in a light session"):
        s.move("lamp", np.eye(4))
    for bad, words in (((1.0, 2.0), "3 finite numbers"), ((0.0, float("nan"), 0.0), "finite"), ("up", "numbers")):
        with pytest.raises(oclgi.OclgiError, match=words):
            s.move_light(bad)
    s.close()
    with pytest.raises(oclgi.OclgiError, match="closed"):
        s.move_light(POSITIONS[0])
    with pytest.raises(oclgi.OclgiError, match="positions"):
        LightSession(engine, points(), light="lamp")
