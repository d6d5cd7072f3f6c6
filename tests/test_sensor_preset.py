"""``oclgi irradiance``'s default estimate (oclgi/estimators/sensor_preset.py):
a DETP method takes adaptive radii, exact direct light and final gathering
unless ``--plain`` or any of those options is given; the command's values
equal the API's with the same options, bit for bit, and it says what it
chose; other methods and runs that count no emitted light keep their own."""

from pathlib import Path

import numpy as np
import pytest

import oclgi
from cli_run import in_process
from oclgi.estimators.sensor_preset import gather_rays, sensor_options

BOX = Path(__file__).resolve().parents[1] / "scenes" / "cornell_box.toml"
PTS = np.array([[0.0, 0.01, 0.0, 0.0, 1.0, 0.0], [0.2, 0.01, -0.1, 0.0, 1.0, 0.0], [-0.99, 1.0, 0.0, 1.0, 0.0, 0.0]])
RUN = dict(photons=20_000, seed=3)


@pytest.fixture(scope="module")
def engine():
    return oclgi.Engine(oclgi.load_file(BOX), progress=False)


def _cli(monkeypatch, capsys, tmp_path, *extra):
    np.save(tmp_path / "p.npy", PTS)
    res = in_process(monkeypatch, capsys, tmp_path, "irradiance", BOX, "--points", "p.npy", "-o", "e.npy",
                     "--photons", RUN["photons"], "--seed", RUN["seed"], *extra)
    assert res.returncode == 0, res.stderr
    return np.load(tmp_path / "e.npy"), res.stderr


def test_the_default_is_the_preset(engine, tmp_path, monkeypatch, capsys):
    got, err = _cli(monkeypatch, capsys, tmp_path)
    want = engine.irradiance(PTS, **RUN, radius_mode="adaptive", direct="exact", gather=1024).irradiance
    assert np.array_equal(got, want)
    assert "final gathering with 1,024 rays a point" in err and "--plain" in err
    plain, err = _cli(monkeypatch, capsys, tmp_path, "--plain")
    assert np.array_equal(plain, engine.irradiance(PTS, **RUN).irradiance)
    assert "final gathering" not in err
    assert not np.array_equal(plain, got)


def test_an_option_given_sets_them_yourself(engine, tmp_path, monkeypatch, capsys):
    got, err = _cli(monkeypatch, capsys, tmp_path, "-O", "direct=exact")
    assert np.array_equal(got, engine.irradiance(PTS, **RUN, direct="exact").irradiance)
    assert "final gathering" not in err
    got, _ = _cli(monkeypatch, capsys, tmp_path, "--method", "photon_map")
    assert np.array_equal(got, engine.irradiance(PTS, **RUN, method="photon_map").irradiance)
    got, _ = _cli(monkeypatch, capsys, tmp_path, "-O", "count_emitted=false")
    assert np.array_equal(got, engine.irradiance(PTS, **RUN, count_emitted=False).irradiance)


def test_the_rays_shrink_with_the_points():
    assert gather_rays(3) == gather_rays(256) == 1024
    assert gather_rays(4096) == 64 and gather_rays(1 << 14) == 16 and gather_rays(1 << 15) == 0
    assert sensor_options("detp", {}, 10**6) == {"radius_mode": "adaptive", "direct": "exact"}
    assert sensor_options("photon_map", {}, 10) == {} == sensor_options("detp", {"gather": 0}, 10)
