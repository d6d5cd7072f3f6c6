"""Parameter updates (oclgi/scene_parameters.py): each kind of change recomputes
only what depends on it (counted: photon paths traced, camera points
traced, sums redone, on the store's tracer), and the result equals a fresh
engine or session made with the new values, bit for bit."""

import numpy as np
import pytest

import oclgi
from analytic_scenes import translation
from test_session import _points, _scene

PHOTONS = 8_000
LEFT = "material.CornellBox-Original.obj:leftWall.albedo"
CAM = dict(position=(0, 1, 3.94), look_at=(0, 1, 0), fov=39.3, width=20, height=20)


def _room(scenes_dir, left=None, light=None):
    """The Cornell box with the bunny, a point light named lamp; the left
    wall's albedo and the lamp's intensity as given (the load's, else)."""
    scene = _scene(scenes_dir)
    scene.camera = oclgi.Camera(**CAM)
    if left is not None:
        m = next(m for m in scene.materials if m.name.endswith("leftWall"))
        m.albedo = left
    scene.point_lights = [oclgi.PointLight(position=(0.0, 1.5, 0.0), intensity=light or (1.0, 1.0, 1.0), name="lamp")]
    return scene


@pytest.fixture()
def engine(scenes_dir):
    return oclgi.Engine(_room(scenes_dir))


def test_engine_update_equals_an_engine_loaded_with_the_values(scenes_dir, engine):
    params = engine.parameters()
    assert params[LEFT] == (0.63, 0.065, 0.05)
    params[LEFT] = (0.2, 0.5, 0.2)
    params["light.lamp.intensity"] = (2.0, 1.0, 0.5)
    params["photons"] = 12_000
    done = params.update()
    assert done.changed == sorted([LEFT, "light.lamp.intensity", "photons"]) and done.tables
    loaded = oclgi.Engine(_room(scenes_dir, left=(0.2, 0.5, 0.2), light=(2.0, 1.0, 0.5)))
    assert engine.compiled.fingerprint() == loaded.compiled.fingerprint()
    a = engine.render(width=16, height=16)  # photons: the updated default
    b = loaded.render(width=16, height=16, photons=12_000)
    assert a.stats.photons == 12_000 and np.array_equal(a.radiance, b.radiance)


def test_an_engine_update_does_not_reach_open_sessions(scenes_dir, engine, rng):
    s = oclgi.Session(engine, _points(engine, rng, 50), photons=PHOTONS, radius=0.05)
    before = s.accumulators()
    params = engine.parameters()
    params[LEFT] = (0.9, 0.9, 0.9)
    params.update()
    assert np.array_equal(s.accumulators(), before) and s.parameters()[LEFT] == (0.63, 0.065, 0.05)
    s.close()


def _fresh(session, **kw):
    args = dict(method=session.params.method, photons=session.params.photons, radius=session.params.radius,
                seed=session.params.seed, max_depth=session.params.max_depth)
    args.update(kw)
    return oclgi.Session(session.engine, None, camera=session.view.cam, **args)


CASES = {
    "albedo": ({LEFT: (0.2, 0.6, 0.2)}, dict(paths=PHOTONS, points=0, resummed=True)),
    "light": ({"light.lamp.position": (0.3, 1.2, -0.2)}, dict(paths=PHOTONS, points=0, resummed=True)),
    "seed": ({"seed": 99}, dict(paths=PHOTONS, points=0, resummed=True)),
    "more photons": ({"photons": PHOTONS + 3_000}, dict(paths=3_000, points=0, resummed=False)),
    "fewer photons": ({"photons": PHOTONS - 3_000}, dict(paths=0, dropped=3_000, points=0, resummed=False)),
    "estimator": ({"method": "detp_ray_map", "radius": 0.07}, dict(paths=0, points=0, resummed=True)),
    "camera": ({"camera": oclgi.Camera(position=(0.4, 1.1, 3.0), look_at=(0, 0.7, 0), fov=45.0, width=18,
                                       height=14)}, dict(paths=0, points=18 * 14, resummed=True)),
}


@pytest.mark.parametrize("case", list(CASES))
def test_session_update_recomputes_only_what_depends_on_it(engine, case):
    changes, expect = CASES[case]
    s = oclgi.Session(engine, None, photons=PHOTONS, radius=0.05)
    s.move("bunny", translation(0.2, 0.0, 0.1))
    store = s.store
    launches = store.tracer.launches
    params = s.parameters()
    for k, v in changes.items():
        params[k] = v
    done = params.update()
    assert done.changed == sorted(changes) and done.paths_traced == expect["paths"]
    assert done.paths_dropped == expect.get("dropped", 0) and done.points_traced == expect["points"]
    assert done.resummed == expect["resummed"]
    # what the store's tracers did: every path traced anew, the added ones only, or none
    if expect["paths"] == PHOTONS:
        assert s.store is not store and s.store.tracer.launches == 1
    elif expect["paths"]:
        assert s.store.tracer.launches == 0 and s.store.added_paths == expect["paths"]
    elif s.store is store:
        assert store.tracer.launches == launches
    else:  # fewer paths: the first ones copied
        assert s.store.tracer.launches == 0 and s.store.added is None
    fresh = _fresh(s)
    assert np.array_equal(s.accumulators(), fresh.accumulators())
    assert np.array_equal(s.render()[0], fresh.render()[0])
    # and it goes on: a move after the update stays exact
    s.move("bunny", translation(-0.1, 0.0, 0.1))
    fresh.close()
    fresh = _fresh(s)
    assert np.array_equal(s.accumulators(), fresh.accumulators())
    s.close()
    fresh.close()


def test_a_material_update_equals_a_scene_loaded_with_it(scenes_dir, engine):
    s = oclgi.Session(engine, None, photons=PHOTONS, radius=0.05)
    s.move("bunny", translation(0.2, 0.0, 0.1))
    params = s.parameters()
    params[LEFT] = (0.2, 0.6, 0.2)
    params["light.lamp.intensity"] = (3.0, 3.0, 3.0)
    params.update()
    loaded = oclgi.Engine(_room(scenes_dir, left=(0.2, 0.6, 0.2), light=(3.0, 3.0, 3.0)))
    loaded.move("bunny", translation(0.2, 0.0, 0.1))
    other = oclgi.Session(loaded, None, photons=PHOTONS, radius=0.05)
    assert np.array_equal(s.accumulators(), other.accumulators())
    assert np.array_equal(s.render()[0], other.render()[0])


def test_photon_map_session_updates(engine, rng):
    s = oclgi.PhotonMapSession(engine, _points(engine, rng, 60), photons=PHOTONS, k=20, mode="exact")
    s.move("bunny", translation(0.2, 0.0, 0.1))
    params = s.parameters()
    params["photons"] = PHOTONS + 2_000
    assert params.update().paths_traced == 2_000
    fresh = oclgi.PhotonMapSession(s.engine, s.points.copy(), photons=PHOTONS + 2_000, k=20, mode="exact")
    assert np.array_equal(s.accumulators(), fresh.accumulators())
    params[LEFT] = (0.3, 0.3, 0.9)
    assert params.update().paths_traced == PHOTONS + 2_000
    fresh = oclgi.PhotonMapSession(s.engine, s.points.copy(), photons=PHOTONS + 2_000, k=20, mode="exact")
    assert np.array_equal(s.accumulators(), fresh.accumulators())
    params["radius"] = 0.2
    with pytest.raises(oclgi.OclgiError, match="no radius to change"):
        params.update()


def test_bad_values_are_refused_and_change_nothing(engine, rng):
    s = oclgi.Session(engine, _points(engine, rng, 30), photons=PHOTONS, radius=0.05)
    before = s.accumulators()
    params = s.parameters()
    for key, value, words in (("material.nope.albedo", (1, 1, 1), r"no parameter 'material\.nope\.albedo'"),
                              (LEFT, (0.1, 0.2), "takes 3 finite numbers"),
                              ("light.lamp.position", (0.0, float("nan"), 0.0), "finite"),
                              # a session over points has no camera
                              ("camera", engine.view_camera(), "no parameter 'camera'")):
        with pytest.raises(oclgi.OclgiError, match=words):
            params[key] = value
    for key, value, words in ((LEFT, (2.0, 0.1, 0.1), "albedo"), ("photons", 0, "photons"),
                              ("method", "photon_map", "no exact incremental update"),
                              ("light.lamp.intensity", (-1.0, 1.0, 1.0), "intensity")):
        params[key] = value
        with pytest.raises(oclgi.OclgiError, match=words):
            params.update()
        assert np.array_equal(s.accumulators(), before), key
        assert params[key] != value, "a refused value is not kept pending"
    assert params.update().changed == []  # nothing pending, nothing done
    s.close()
