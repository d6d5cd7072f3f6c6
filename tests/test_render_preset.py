"""``oclgi render``'s default estimate (oclgi/estimators/render_preset.py): a
DETP method takes 16 samples a pixel, exact direct light and the indirect
light gathered at one pixel in 3 x 3, unless ``--plain``, ``--spp`` or any
of its options is given; the command's image equals the API's with the same
settings, bit for bit, and it says what it chose; other methods and runs
that count no emitted light keep their own; large images take fewer samples
and a wider spacing. A preset run resumed from its checkpoint equals the
uninterrupted one (tests/test_checkpoint.py runs the command's default)."""

from pathlib import Path

import numpy as np
import pytest

import oclgi
from cli_run import in_process
from oclgi.estimators.render_preset import MAX_HITS, MAX_SAMPLES, render_settings
from oclgi.io import read_image

BOX = Path(__file__).resolve().parents[1] / "scenes" / "cornell_box.toml"
RUN = dict(photons=20_000, seed=3, width=24, height=16)


@pytest.fixture(scope="module")
def engine():
    return oclgi.Engine(oclgi.load_file(BOX), progress=False)


def _cli(monkeypatch, capsys, tmp_path, *extra):
    res = in_process(monkeypatch, capsys, tmp_path, "render", BOX, "-o", "x.exr", "--no-png", "--photons",
                     RUN["photons"], "--seed", RUN["seed"], "--width", RUN["width"], "--height", RUN["height"], *extra)
    assert res.returncode == 0, res.stderr
    return read_image(tmp_path / "x.exr")[..., :3], res.stderr


def _api(engine, **kw):
    return engine.render(**RUN, **kw).radiance


def test_the_default_is_the_preset(engine, tmp_path, monkeypatch, capsys):
    got, err = _cli(monkeypatch, capsys, tmp_path)
    want = _api(engine, spp=16, direct="exact", direct_samples=4, direct_mis="light", gather=128, gather_spacing=3)
    assert np.array_equal(got, want)
    assert "16 samples a pixel" in err and "one pixel in 3 x 3" in err and "--plain" in err
    plain, err = _cli(monkeypatch, capsys, tmp_path, "--plain")
    assert np.array_equal(plain, _api(engine))
    assert "samples a pixel" not in err
    assert not np.array_equal(plain, got)


def test_given_settings_set_them_yourself(engine, tmp_path, monkeypatch, capsys):
    got, err = _cli(monkeypatch, capsys, tmp_path, "--spp", "2")
    assert np.array_equal(got, _api(engine, spp=2)) and "samples a pixel" not in err
    got, _ = _cli(monkeypatch, capsys, tmp_path, "-O", "direct=exact")
    assert np.array_equal(got, _api(engine, direct="exact"))
    got, _ = _cli(monkeypatch, capsys, tmp_path, "--method", "photon_map")
    assert np.array_equal(got, _api(engine, method="photon_map"))
    got, _ = _cli(monkeypatch, capsys, tmp_path, "-O", "count_emitted=false")
    assert np.array_equal(got, _api(engine, count_emitted=False))


def test_large_images_take_fewer_samples_and_a_wider_spacing():
    small = render_settings("detp", {}, False, 128, 128)
    assert small == {"spp": 16, "direct": "exact", "direct_samples": 4, "direct_mis": "light", "gather": 128,
                     "gather_spacing": 3}
    for w, h in ((256, 256), (512, 512), (1920, 1080), (4096, 4096), (16384, 16384)):
        s = render_settings("detp", {}, False, w, h)
        assert 1 <= s["spp"] <= 16 and (s["spp"] == 1 or w * h * s["spp"] <= MAX_SAMPLES)
        assert 3 <= s["gather_spacing"] <= 64
        assert s["gather_spacing"] == 64 or (w * h / s["gather_spacing"] ** 2) * s["gather"] <= MAX_HITS
    assert render_settings("detp", {}, False, 1920, 1080)["spp"] == 2
    assert render_settings("photon_map", {}, False, 8, 8) == {} == render_settings("detp", {}, True, 8, 8)
    assert render_settings("detp", {"gather": 0}, False, 8, 8) == {}
