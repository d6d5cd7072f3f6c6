"""IES profiles (oclgi/scene/ies.py, IesLight in oclgi/scene/lights.py,
the IES kind of kernels/light.h) against the file's own table.

Synthetic LM-63 files with known distributions: a light 1 above a black
plane (tests/test_lights.py's set-up: direct light only, plain DETP and
the default estimator, equal bit for bit), whose irradiance at points in
the directions of tabulated angles is I(gamma, C) cos(gamma) / r^2 of the
table (tests/reference.py's lookup, straight from the file's numbers),
within about four standard errors of the photon count each disc catches;
the power is the table's flux / 683 (photometry.py's convention) exactly,
and the photons carry it; symmetric files expand to their whole tables;
bad files and tables are refused in one line.
"""

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from reference import ies_candela
from analytic_scenes import disc_mean, on_plane, square
from test_lights import _both, _scene_file, light_samples, refused_in_one_line

import oclgi
from oclgi.errors import OclgiError, OclgiWarning
from oclgi.photometry import LUMENS_PER_WATT
from oclgi.scene import ies, lights

H = 1.0  # the light's height over the plane


def ies_text(vertical, horizontal, candela, lumens=-1.0, multiplier=1.0, ballast=1.0, ptype=1, tilt="NONE",
             header="IESNA:LM-63-2002") -> str:
    """An LM-63 file: ``candela`` (H, V) or flat, one row per horizontal angle."""
    values = np.asarray(candela, np.float64).ravel()
    rows = [" ".join(f"{x:g}" for x in values[k:k + 10]) for k in range(0, len(values), 10)]
    return "\r\n".join([header, "[TEST] tests/test_ies.py", "[MANUFAC] oclgi", f"TILT={tilt}",
                        f"1 {lumens:g} {multiplier:g} {len(vertical)} {len(horizontal)} {ptype} 2 0 0 0",
                        f"{ballast:g} 1.0 50", " ".join(f"{a:g}" for a in vertical),
                        " ".join(f"{a:g}" for a in horizontal), *rows]) + "\r\n"


# An asymmetric downlight: 0..90 degrees down in 10 degree steps, C at 0, 90, 180, 270 (and 360 = 0).
VERT = np.arange(0.0, 91.0, 10.0)
HORIZ = np.array([0.0, 90.0, 180.0, 270.0, 360.0])
SIDES = np.array([1.0, 0.5, 0.2, 0.8, 1.0])  # by horizontal angle
BASE = 200.0 * np.cos(np.radians(VERT)) + 20.0
TABLE = SIDES[:, None] * BASE[None, :]
TABLE[2, 3] = 0.0  # C = 180, gamma = 30: a dark bin


def _file(tmp_path, text, name="lamp.ies"):
    (tmp_path / name).write_text(text)
    return tmp_path / name


def _scene(tmp_path, light: dict, table="point_light", photons=2_000_000, seed=3):
    v, f = square(2.0)
    return oclgi.load_dict({"mesh": [{"vertices": v, "faces": f, "albedo": [0, 0, 0]}],
                            table: [{"position": [0, H, 0], **light}],
                            "photons": {"count": photons, "seed": seed, "max_depth": 1}}, base_dir=tmp_path)


def _expected(profile_lookup, nadir, c0, xz, d):
    """Disc means of E = I cos(gamma) / r^2 (W/m^2 per channel of a white light) on the plane y = 0."""
    nadir, c0 = np.asarray(nadir, float), np.asarray(c0, float)
    c90 = np.cross(c0, nadir)

    def exact(x, z):
        w = np.stack([x, np.full_like(x, -H), z], axis=-1)
        r = np.linalg.norm(w, axis=-1)
        w = w / r[..., None]
        gamma = np.degrees(np.arccos(np.clip(w @ nadir, -1, 1)))
        c = np.degrees(np.arctan2(w @ c90, w @ c0))
        return profile_lookup(gamma, c) * (H / r) / r**2 / LUMENS_PER_WATT

    return np.array([disc_mean(x, z, d, 160, exact) for x, z in xz])


# (gamma, C) of the points: tabulated angles, discs well inside their bins
ANGLES = [(g, c) for g in (10.0, 20.0, 30.0, 40.0) for c in (0.0, 90.0, 180.0, 270.0)] + [(0.0, 0.0)]


@pytest.mark.parametrize("frame", [
    {},  # the defaults: nadir down, C0 along +x (so C90 along -z)
    {"matrix": [[0, 1, 0], [0, 0, 1], [1, 0, 0]]},  # C0 along +z, C90 along +x, zenith up
])
def test_irradiance_under_an_ies_light_is_the_files_table(tmp_path, frame):
    path = _file(tmp_path, ies_text(VERT, HORIZ, TABLE))
    engine = oclgi.Engine(_scene(tmp_path, {"ies": path.name, **frame}))
    light = engine.scene.lights[0]
    nadir, c0 = np.array(light.direction), np.array(light.c0)
    assert np.allclose(nadir, [0, -1, 0]) and np.allclose(c0, [1, 0, 0] if not frame else [0, 0, 1])
    c90 = np.cross(c0, nadir)
    xz = []
    for g, c in ANGLES:  # the point of the plane in the direction (gamma, C)
        t = math.tan(math.radians(g))
        w = H * t * (math.cos(math.radians(c)) * c0 + math.sin(math.radians(c)) * c90)
        xz.append((w[0], w[2]))
    d = 0.06
    e = _both(engine, on_plane(xz), d)
    ref = _expected(lambda g, c: ies_candela(VERT, HORIZ, TABLE, g, c), nadir, c0, xz, d)
    dark = ref == 0
    assert dark.sum() == 1 and e[dark][0] == 0  # the dark bin gets no photon at all
    # each disc's expected segment count: E pi d^2 over one photon's watts
    photon_watts = engine.compiled.total_power[0] / 2_000_000
    n = ref[~dark] * math.pi * d * d / photon_watts
    assert n.min() > 500
    z = (e[~dark] / ref[~dark] - 1) * np.sqrt(n)
    assert np.abs(z).max() < 4.5, z
    assert abs(np.mean(e[~dark] / ref[~dark]) - 1) < 4 / math.sqrt(n.sum())


def _flat(tmp_path, **kw):
    """A downlight of 100 cd everywhere below the horizontal: 2 pi 100 lm, exactly for any bins."""
    return _file(tmp_path, ies_text([0, 45, 90], [0], [100, 100, 100], **kw))


def test_power_is_the_files_lumens_over_683(tmp_path):
    flux = 2 * math.pi * 100.0
    path = _flat(tmp_path, lumens=flux)
    profile = ies.read(path)
    assert profile.rated == pytest.approx(flux, rel=1e-6) and profile.lumens == pytest.approx(flux, rel=1e-12)
    engine = oclgi.Engine(_scene(tmp_path, {"ies": path.name}, photons=100_000))
    np.testing.assert_allclose(engine.compiled.total_power, flux / LUMENS_PER_WATT, rtol=1e-12)
    # the photons carry it, each the same share
    s, _ = engine.trace(photons=100_000)
    assert s["power"][:, 0].astype(np.float64).sum() == pytest.approx(flux / LUMENS_PER_WATT, rel=1e-4)
    # lumens and candela rescale the table; colour keeps the luminance
    for key, value, want in (("lumens", 500.0, 500.0), ("candela", 50.0, flux / 2)):
        sc = _scene(tmp_path, {"ies": path.name, key: value, "colour": [1.0, 0.5, 0.25]}, photons=1000)
        watts = oclgi.Engine(sc).compiled.total_power
        assert LUMENS_PER_WATT * float(watts @ [0.2126, 0.7152, 0.0722]) == pytest.approx(want, rel=1e-9)
        assert watts[0] / watts[2] == pytest.approx(4.0)
    # the file's multiplier and ballast factor scale the candela
    assert ies.read(_flat(tmp_path, multiplier=2.0, ballast=0.5)).lumens == pytest.approx(flux)
    assert ies.read(_flat(tmp_path, multiplier=3.0)).lumens == pytest.approx(3 * flux)


def test_an_ies_spot_is_the_profile_times_the_cone(tmp_path):
    """With ``ies`` in a spot_light, the profile times the spot's smoothstep:
    power by quadrature of the two, photons within phi_max, irradiance."""
    path = _file(tmp_path, ies_text(VERT, HORIZ, TABLE))
    sc = _scene(tmp_path, {"ies": path.name, "direction": [0, -1, 0], "cone_angle": 35, "cone_delta": 15},
                table="spot_light")
    engine = oclgi.Engine(sc)
    light = sc.lights[0]
    assert light.table == "spot_light" and light.cone_angle == 35
    # quadrature over the sphere of I(gamma, C) x smoothstep
    ng, nc = 2000, 360
    g = (np.arange(ng) + 0.5) / ng * 90.0
    c = (np.arange(nc) + 0.5) / nc * 360.0
    gg, cc = np.meshgrid(g, c)
    spot = lights.SpotLight((0, 0, 0), (0, -1, 0), (1, 1, 1), 35, 15)
    f = ies_candela(VERT, HORIZ, TABLE, gg, cc) * spot.profile(np.cos(np.radians(gg)))
    flux = float((f * np.sin(np.radians(gg))).sum() * np.radians(90 / ng) * np.radians(360 / nc))
    assert engine.compiled.total_power[0] * LUMENS_PER_WATT == pytest.approx(flux, rel=2e-4)
    s, _ = engine.trace(photons=100_000)
    units = s["power"] / engine.photon_watts(100_000)
    assert units.max() <= 1 + 1e-6 and (units[:, 0] < 0.5).mean() > 0.02  # the band's photons carry less
    xz = [(0.0, 0.0), (math.tan(math.radians(20)), 0.0), (0.0, math.tan(math.radians(20))), (1.2, 0.0)]
    d = 0.06
    e = _both(engine, on_plane(xz), d)
    ref = _expected(lambda g, c: ies_candela(VERT, HORIZ, TABLE, g, c) * spot.profile(np.cos(np.radians(g))),
                    [0, -1, 0], [1, 0, 0], xz, d)
    assert e[3] == 0 and ref[3] == 0  # past the cone
    n = ref[:3] * math.pi * d * d / (engine.compiled.total_power[0] / 2_000_000)
    assert np.abs((e[:3] / ref[:3] - 1) * np.sqrt(n)).max() < 4.5


@pytest.mark.parametrize("last", [0, 90, 180])
def test_symmetric_files_expand_to_their_whole_table(tmp_path, last):
    """A file with the last horizontal angle 0, 90 or 180 is its whole-circle
    expansion: the same profile, the same photons bit for bit as the file
    written out over 0..360, and the reference's folded lookup."""
    vert = np.array([0.0, 30.0, 60.0, 90.0])
    horiz = {0: [0.0], 90: [0.0, 45.0, 90.0], 180: [0.0, 60.0, 120.0, 180.0]}[last]
    rng = np.random.default_rng(last)
    table = np.round(rng.uniform(10, 100, (len(horiz), len(vert))), 2)  # as the file prints them
    sym = ies.parse(ies_text(vert, horiz, table).encode())
    # the whole table by hand: mirror images at 180 - C, 360 - C
    if last == 0:
        full_h, full = [0.0, 90.0, 180.0, 270.0, 360.0], np.repeat(table, 5, axis=0)
    elif last == 90:
        full_h = [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0, 360.0]
        full = table[[0, 1, 2, 1, 0, 1, 2, 1, 0]]
    else:
        full_h = [0.0, 60.0, 120.0, 180.0, 240.0, 300.0, 360.0]
        full = table[[0, 1, 2, 3, 2, 1, 0]]
    whole = ies.parse(ies_text(vert, full_h, full).encode())
    gamma, c = rng.uniform(0, 90, 2000), rng.uniform(-360, 720, 2000)
    ref = ies_candela(vert, horiz, table, gamma, c)
    assert np.array_equal(sym.intensity(gamma, c), ref) and np.array_equal(whole.intensity(gamma, c), ref)
    if last != 0:  # one plane is its own table (one bin round the circle); the others equal their expansions
        assert np.array_equal(sym.horizontal, whole.horizontal) and np.array_equal(sym.candela, whole.candela)
        _file(tmp_path, ies_text(vert, horiz, table), "sym.ies")
        _file(tmp_path, ies_text(vert, full_h, full), "whole.ies")
        pts = on_plane([(0.3, 0.2), (-0.4, 0.1), (0.1, -0.5)])
        sums = [oclgi.Engine(_scene(tmp_path, {"ies": name}, photons=50_000)).irradiance(pts, radius=0.2)
                .accumulators for name in ("sym.ies", "whole.ies")]
        assert sums[0].sum() > 0 and np.array_equal(sums[0], sums[1])
    assert sym.lumens == pytest.approx(whole.lumens, rel=1e-12)


def test_light_pdf_dir_of_an_ies_light_is_its_sampling_density(cl_env):
    """The mean of 1 / pdf over the kind's samples is the solid angle it
    emits into (the lower hemisphere here, 2 pi), and the pdf is that of
    the bins' candela x solid angle."""
    profile = ies.parse(ies_text(VERT, HORIZ, TABLE + 1.0).encode())  # no dark bin
    light = lights.IesLight((0.0, 0.0, 0.0), profile, direction=(0.0, -1.0, 0.0), c0=(0.0, 0.0, 1.0))
    rec = light.record(None)
    out = light_samples(cl_env, [rec[key] for key in ("kind", "p", "e1", "e2", "a", "b")], rec["table"], seed=7)
    d, pdf = out[:, 3:6].astype(np.float64), out[:, 7].astype(np.float64)
    assert (pdf > 0).all() and (d[:, 1] <= 1e-6).all()  # all downwards
    assert abs(np.mean(1 / pdf) / (2 * math.pi) - 1) < 0.01
    # the pdf is candela / flux (a bin's probability over its solid angle)
    gamma = np.degrees(np.arccos(np.clip(-d[:, 1], -1, 1)))
    c90 = np.cross([0.0, 0.0, 1.0], [0.0, -1.0, 0.0])
    c = np.degrees(np.arctan2(d @ c90, d[:, 2]))
    want = ies_candela(VERT, HORIZ, TABLE + 1.0, gamma, c) / profile.lumens
    # away from the bins' edges (C 45, 135, ...; gamma 5, 15, ...), where float32 may fall either side
    uc, ug = np.mod(c - 45, 90), np.mod(gamma - 5, 10)
    inner = (np.minimum(uc, 90 - uc) > 0.1) & (np.minimum(ug, 10 - ug) > 0.05)
    assert inner.mean() > 0.98
    np.testing.assert_allclose(pdf[inner], want[inner], rtol=1e-3)


def test_mitsuba_export_leaves_ies_lights_out_with_a_warning(tmp_path):
    sc = _scene(tmp_path, {"ies": _file(tmp_path, ies_text(VERT, HORIZ, TABLE)).name}, photons=1000)
    with pytest.warns(OclgiWarning, match=r"point_light\[0\]: Mitsuba 3 has no IES profiles; lamp\.ies is left out"):
        assert lights.mitsuba_emitters(None, sc) == {}


def test_the_shipped_downlight_and_its_scene(scenes_dir):
    profile = ies.read(scenes_dir / "ies" / "downlight.ies")
    assert profile.rated == pytest.approx(profile.lumens, rel=1e-5) and profile.rated == pytest.approx(1000, rel=1e-3)
    g = np.arange(0.0, 90.0, 5.0)
    np.testing.assert_allclose(profile.intensity(g, 0.0), profile.peak * np.cos(np.radians(g)), rtol=2e-5)
    sc = oclgi.load_file(scenes_dir / "cornell_ies.toml")
    light = sc.lights[0]
    assert isinstance(light, lights.IesLight) and light.flux * light.scale == pytest.approx(3000.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        engine = oclgi.Engine(sc)
    assert LUMENS_PER_WATT * float(engine.compiled.total_power @ [0.2126, 0.7152, 0.0722]) == pytest.approx(3000.0)
    assert engine.render(photons=20_000, width=16, height=16).radiance.mean() > 0


# -- refused, in one line -----------------------------------------------------------------------------------------

GOOD = ies_text([0, 45, 90], [0], [100, 80, 0])


def _swap(old, new):
    assert old in GOOD
    return GOOD.replace(old, new, 1)


@pytest.mark.parametrize("text, match", [
    ("", r"no TILT= line"),
    ("IESNA:LM-63-2002\r\n[TEST] x\r\n", r"no TILT= line"),
    (_swap("TILT=NONE", "TILT=INCLUDE"), r"line 4: TILT=INCLUDE; only TILT=NONE is read"),
    (_swap("TILT=NONE", "TILT=lamp.tlt"), r"TILT=lamp\.tlt; only TILT=NONE"),
    (_swap("3 1 1 2 0 0 0", "3 1 3 2 0 0 0"), r"photometric type 3 \(type A\); only type C"),
    (_swap("3 1 1 2 0 0 0", "3 1 2 2 0 0 0"), r"photometric type 2 \(type B\)"),
    (_swap("1 -1 1 3 1", "1 -1 1 3000000 1"), r"number of vertical angles is 3e\+06"),
    (_swap("1 -1 1 3 1", "1 -1 1 3 1.5"), r"number of horizontal angles is 1\.5"),
    (_swap("1 -1 1 3 1", "1 -1 1 1 1"), r"one vertical angle; at least 2"),
    (_swap("1 -1 1 3 1", "1 -1 1 2000 2000"), r"2000 x 2000 candela values; at most 2,097,152"),
    (_swap("1 -1 1 3 1", "1 -1 0 3 1"), r"candela multiplier is 0"),
    (_swap("100 80 0", "100 80"), r"19 numbers after TILT=NONE, expected 20 for 3 vertical and 1 horizontal angles \(1 missing\)"),
    (_swap("100 80 0", "100 80 0 7"), r"21 numbers after TILT=NONE, expected 20 .*\(1 extra\)"),
    (_swap("100 80 0", "100 eighty 0"), r"line 9: candela values: not a number: 'eighty'"),
    (_swap("100 80 0", "100 nan 0"), r"'nan' is not a finite number"),
    (_swap("100 80 0", "100 -80 0"), r"candela value 2 is negative"),
    (_swap("100 80 0", "0 0 0"), r"the candela table emits no light"),
    (_swap("0 45 90", "0 90 45"), r"vertical angles must ascend within 0\.\.180"),
    (_swap("0 45 90", "0 45 200"), r"vertical angles must ascend within 0\.\.180"),
    (_swap("\r\n0\r\n", "\r\n45\r\n"), r"horizontal angles must ascend from 0 to 0, 90, 180 or 360"),
    ("TILT=NONE\r\n\x00\x01", r"not a text file"),
])
def test_bad_ies_files_are_refused_in_one_line(tmp_path, text, match):
    path = tmp_path / "bad.ies"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(OclgiError, match=match) as err:
        ies.read(path, "point_light[0].ies")
    assert "\n" not in str(err.value) and str(err.value).startswith("point_light[0].ies: ")


def test_too_large_and_missing_files(tmp_path, monkeypatch):
    monkeypatch.setattr(ies, "MAX_BYTES", 100)
    path = _file(tmp_path, GOOD + " " * 200)
    with pytest.raises(OclgiError, match=r"lamp\.ies: larger than 0 MiB"):
        ies.read(path)
    with pytest.raises(OclgiError, match=r"IES file not found"):
        ies.read(tmp_path / "none.ies")
    with pytest.raises(OclgiError, match=r"is a folder"):
        ies.read(tmp_path)


PL = '[[point_light]]\nposition = [0, 1, 0]\n'
LAMP = PL + 'ies = "lamp.ies"\n'


@pytest.mark.parametrize("table, match", [
    (PL + 'ies = "none.ies"\n', r"point_light\[0\]\.ies: IES file not found"),
    (LAMP + 'intensity = [1, 1, 1]\n', r"point_light\[0\]\.intensity: an IES light's intensity is its file's candela"),
    (LAMP + 'candela = 5\nlumens = 5\n', r"give candela \(the peak\) or lumens \(the flux\), not both"),
    (LAMP + 'lumens = -5\n', r"point_light\[0\]\.lumens: expected a luminous flux \(lm\) > 0"),
    (PL + 'intensity = [1, 1, 1]\nlumens = 5\n', r"point_light\[0\]\.lumens goes with ies"),
    (PL + 'intensity = [1, 1, 1]\ndirection = [0, -1, 0]\n', r"point_light\[0\]\.direction goes with ies"),
    ('[[spot_light]]\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\nintensity = [1, 1, 1]\nc0 = [1, 0, 0]\n',
     r"spot_light\[0\]\.c0 goes with ies"),
    (LAMP + 'c0 = [0, 2, 0]\n', r"point_light\[0\]\.c0: must not be parallel to the direction"),
    (LAMP + 'matrix = [[1, 0, 0], [0, 1, 0], [0, 0, -1]]\n', r"point_light\[0\]\.matrix: expected a rotation"),
    (LAMP + 'matrix = [[1, 0, 0], [0, 1, 0]]\n', r"point_light\[0\]\.matrix: expected 3 rows of 3 numbers"),
    (LAMP + 'matrix = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\ndirection = [0, -1, 0]\n',
     r"give matrix or direction, not both"),
    ('[[spot_light]]\nposition = [0, 1, 0]\nies = "lamp.ies"\n', r"spot_light\[0\]\.direction: required"),
    ('[[spot_light]]\nposition = [0, 1, 0]\nies = "up.ies"\ndirection = [0, -1, 0]\ncone_angle = 10\n',
     r"no light of the IES profile falls within the spot's cone"),
    (PL + 'ies = 5\n', r"point_light\[0\]\.ies: expected an IES file name"),
])
def test_bad_ies_light_tables_fail_in_one_line(cli_fails, tmp_path, table, match):
    _file(tmp_path, GOOD)
    _file(tmp_path, ies_text([90, 135, 180], [0], [100, 80, 0]), "up.ies")  # light above the horizontal only
    _scene_file(tmp_path, table)
    refused_in_one_line(cli_fails, tmp_path, match)


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_mangled_files_parse_or_fail_in_one_line(data):
    """Any bytes changed, cut or added: a profile or one OclgiError line, never another exception."""
    raw = bytearray(ies_text(VERT, HORIZ, TABLE).encode())
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, len(raw) - 1))
        op = data.draw(st.sampled_from(["set", "cut", "add"]))
        b = data.draw(st.sampled_from(list(b"0123456789.-+eE ,\r\n\t9xTN=") + [0, 255]))
        if op == "set":
            raw[k] = b
        elif op == "cut":
            del raw[k:k + data.draw(st.integers(1, 40))]
        else:
            raw[k:k] = bytes([b]) * data.draw(st.integers(1, 8))
        if not raw:
            raw = bytearray(b"x")
    try:
        profile = ies.parse(bytes(raw), "f")
    except OclgiError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("f: ")
    else:
        assert profile.lumens > 0 and np.isfinite(profile.candela).all()
