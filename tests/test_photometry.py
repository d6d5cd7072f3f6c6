"""Photometric units (oclgi/photometry.py): a point light in candela and an
area light in lumens give the illuminance in lux that the inverse-square
law gives, within the photon noise; `irradiance --units photometric` writes
lux."""

import math

import numpy as np
import pytest
from cli_run import in_process

import oclgi
from oclgi.photometry import illuminance_lux, intensity_from_candela

FLOOR = {"vertices": [[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], "faces": [[0, 2, 1], [0, 3, 2]],
         "albedo": [0.0, 0.0, 0.0]}  # black: direct light only
SENSOR = np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])


def _lux(scene, photons, radius):
    est = oclgi.Engine(oclgi.load_dict(scene)).irradiance(SENSOR, photons=photons, radius=radius)
    return float(illuminance_lux(est.irradiance)[0])


def test_a_1000_cd_point_light_2_m_above_reads_250_lux():
    # the disc (radius 0.1 at 2 m) averages I h / (h^2 + rho^2)^1.5: 0.25% under the centre's 250 lux
    photons, radius = 2_000_000, 0.1
    lux = _lux({"mesh": [FLOOR], "point_light": [{"position": [0, 2, 0], "candela": 1000}]}, photons, radius)
    expect = 1000 * 2 * (1 - 2 / math.sqrt(4 + radius**2)) / radius**2
    hits = photons * (1 - 2 / math.sqrt(4 + radius**2)) / 2  # photons through the disc's solid angle
    assert abs(lux - expect) < 4 * expect / math.sqrt(hits), (lux, expect)
    assert expect == pytest.approx(250, rel=0.003)
    # candela of a coloured light: its luminance, not each channel, is the candela
    rgb = intensity_from_candela(683.0, colour=(1.0, 0.5, 0.25))
    assert float(np.dot(rgb, [0.2126, 0.7152, 0.0722])) == pytest.approx(1.0)


def test_a_lumen_rated_area_light_gives_its_illuminance():
    # a 0.1 m square emitting 1000 lm downwards from 2 m: intensity Phi / pi along its normal, E = Phi / (pi h^2)
    s = 0.05
    light = {"vertices": [[-s, 2, -s], [s, 2, -s], [s, 2, s], [-s, 2, s]], "faces": [[0, 1, 2], [0, 2, 3]],
             "lumens": 1000, "albedo": [0, 0, 0]}
    photons, radius = 2_000_000, 0.1
    lux = _lux({"mesh": [FLOOR, light]}, photons, radius)
    expect = 1000 / (math.pi * 4)  # 79.6 lux; the square's size and the disc change it by under 0.5%
    hits = photons * radius**2 / 4 * 2  # cosine-weighted: about 2 (r / h)^2 of the photons reach the disc
    assert abs(lux - expect) < 0.005 * expect + 4 * expect / math.sqrt(hits), (lux, expect)


def test_irradiance_command_writes_lux(tmp_path, monkeypatch, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text("[[mesh]]\nvertices = [[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]]\n"
                     "faces = [[0, 2, 1], [0, 3, 2]]\nalbedo = [0, 0, 0]\n"
                     "[[point_light]]\nposition = [0, 2, 0]\ncandela = 1000\n")
    np.save(tmp_path / "p.npy", SENSOR)
    args = ("irradiance", scene, "--points", "p.npy", "--photons", 200_000, "--radius", 0.1, "--quiet")
    assert in_process(monkeypatch, capsys, tmp_path, *args, "-o", "w.npy").returncode == 0
    res = in_process(monkeypatch, capsys, tmp_path, *args, "-o", "lux.csv", "--units", "photometric")
    assert res.returncode == 0, res.stderr
    lines = (tmp_path / "lux.csv").read_text().splitlines()
    assert lines[0] == "x,y,z,nx,ny,nz,E_v_lux" and len(lines) == 2
    watts = np.load(tmp_path / "w.npy")
    assert float(lines[1].split(",")[-1]) == pytest.approx(float(illuminance_lux(watts)[0]), rel=1e-8)
    scene.write_text(scene.read_text().replace("candela = 1000", "candela = 1000\nintensity = [1, 1, 1]"))
    res = in_process(monkeypatch, capsys, tmp_path, *args, "-o", "x.npy")
    assert res.returncode == 2 and "give intensity (W/sr) or candela, not both" in res.stderr
