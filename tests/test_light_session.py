"""A light session (oclgi/incremental/light_session.py): the light dragged
among an animation's positions by path reuse, anywhere else by recomputation,
and it says which; the session protocol where it applies."""

import numpy as np
import pytest

import oclgi
from cli_run import in_process
from oclgi.incremental.light_session import LightSession
from oclgi.tracing.light_reuse import LightReuse
from test_light_reuse import AXES, BOX, POSITIONS, RADIUS, box, points

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
    s = LightSession(engine, None, light="lamp", positions=POSITIONS, photons=N, max_depth=6, radius=RADIUS, camera=cam)
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


def test_a_light_path_in_the_scene_file(tmp_path, monkeypatch, capsys):
    """``path`` in a [[point_light]] table: the session's default positions
    and animate's default --light-path, the same frames byte for byte."""
    text = (f'name = "lit"\n[[mesh]]\npath = "{BOX}"\n[mesh.materials.light]\nemission = [0, 0, 0]\n'
            '[[point_light]]\nname = "lamp"\nposition = [0, 1.5, 0]\nintensity = [1, 0.8, 0.6]\n'
            'path = [[-0.5, 1.5, 0.0], [0.5, 1.6, 0.2], [0.0, 1.8, -0.4]]\n'
            '[photons]\ncount = 3000\nmax_depth = 6\n[camera]\nposition = [0, 1, 3.94]\nlook_at = [0, 1, 0]\n'
            'width = 16\nheight = 16\n')
    scene_file = tmp_path / "lit.toml"
    scene_file.write_text(text)
    scene = oclgi.load_file(scene_file)
    assert scene.point_lights[0].path == ((-0.5, 1.5, 0.0), (0.5, 1.6, 0.2), (0.0, 1.8, -0.4))
    s = LightSession(oclgi.Engine(scene), points(), light="lamp", photons=N, radius=RADIUS)
    assert s.reuse.frames == 3 and s.move_light((0.5, 1.6, 0.2)).reused
    s.close()
    common = ["animate", scene_file, "--light", "lamp", "--frames", 4, "--photons", 500, "--quiet"]
    a = in_process(monkeypatch, capsys, tmp_path, *common, "-o", tmp_path / "a")
    b = in_process(monkeypatch, capsys, tmp_path, *common, "-o", tmp_path / "b",
                   "--light-path=-0.5,1.5,0;0.5,1.6,0.2;0,1.8,-0.4")
    assert a.returncode == 0 and b.returncode == 0, (a.stderr, b.stderr)
    for k in range(4):
        name = f"frame_{k:04d}.png"
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    for bad, words in (("path = [[0, 1]]", "every row must have 3"), ("path = []", "expected a list of rows"),
                       ("path = [[0, 1, 1e300]]", "path"), ('path = "up"', "expected a list of rows")):
        scene_file.write_text(text.replace("path = [[-0.5, 1.5, 0.0], [0.5, 1.6, 0.2], [0.0, 1.8, -0.4]]", bad))
        with pytest.raises(oclgi.OclgiError, match=words):
            oclgi.load_file(scene_file)
    scene_file.write_text(text.replace("path = [[-0.5, 1.5, 0.0], [0.5, 1.6, 0.2], [0.0, 1.8, -0.4]]\n", ""))
    r = in_process(monkeypatch, capsys, tmp_path, *common, "-o", tmp_path / "c")
    assert r.returncode == 2 and "has no path in the scene file" in r.stderr


def test_a_light_session_gathers_exactly():
    """Final gathering with the light dragged: each precomputed position
    equals the animation's plain frame (every batch through a fresh
    estimator) bit for bit, sums and irradiance, through the disc index's
    re-weighting; a free position equals a fresh engine's gathered run;
    the gather changes the answer."""
    engine = oclgi.Engine(box(POSITIONS[0]))
    kw = dict(radius=RADIUS, direct="exact", gather=8)
    s = LightSession(engine, points(), light="lamp", positions=POSITIONS, photons=N, seed=3, max_depth=6, **kw)
    assert s.reweighting is not None
    reuse = LightReuse(engine, "lamp", POSITIONS, photons=N, seed=3, max_depth=6)
    frames = reuse.frames_irradiance(points(), **kw)
    plain = reuse.frames_irradiance(points(), radius=RADIUS, direct="exact")
    for j in (2, 0, 3, 1):
        assert s.move_light(POSITIONS[j]).reused
        assert np.array_equal(s.accumulators(), frames[j].accumulators)
        assert np.array_equal(s.irradiance(), frames[j].irradiance)
        assert not np.array_equal(s.irradiance(), plain[j].irradiance)
    free = (0.1, 1.4, 0.1)
    assert not s.move_light(free).reused
    fresh = oclgi.Engine(box(free)).irradiance(points(), photons=N, seed=3, max_depth=6, **kw)
    assert np.array_equal(s.irradiance(), fresh.irradiance)
    s.close()
