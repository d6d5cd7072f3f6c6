"""One reader per run parameter (oclgi/params.py): the command line, the
scene file and the API refuse the same values in the same words and accept
the same values.

Each bad value is given three ways, and the message's text after the name
(``--photons``, ``photons.count``, ``photons``) must be the same:

* the command line, in-process (``oclgi.cli.main``): one ``oclgi: error:``
  line, exit status 2, nothing written;
* a scene file, read by ``load_file`` and by the command line;
* the API: ``Engine.run_params`` (what ``irradiance``, ``render`` and the
  sessions call) or the estimator options of ``Engine.irradiance``.
"""

import dataclasses
import math
import re
import subprocess

import numpy as np
import pytest
from cli_run import run
import small_scene
from small_scene import BOX_MTL as MTL

import oclgi
from oclgi import budget, params
from oclgi.cli import build_parser
from oclgi.errors import OclgiError
from oclgi.scene.description import load_dict, load_file
from oclgi.study import Config

SCENE = '[[mesh]]\npath = "box.obj"\n{mesh}\n[camera]\nposition = [0, 0.5, 3]\nlook_at = [0, 0.3, 0]\n' \
        'width = 4\nheight = 4\n{extra}'
POINTS = np.array([[0, 0.01, 0, 0, 1, 0]], float)


def write_scene(d, extra="", mesh=""):
    return small_scene.write_scene(d, scene=SCENE.format(extra=extra, mesh=mesh))


@pytest.fixture(scope="module")
def engine(tmp_path_factory):
    return oclgi.Engine(load_file(write_scene(tmp_path_factory.mktemp("params"))), progress=False)


ARGPARSE = re.compile(r"^oclgi: error: argument (\S+): (.*) \(see `oclgi \w+ --help`\)$")


def flag_problem(line, flag):
    """The problem an argparse error line states about ``flag``."""
    m = ARGPARSE.match(line)
    assert m and m.group(1) == flag, line
    return m.group(2)


def named_problem(message, name):
    prefix = f"{name}: "
    assert message.startswith(prefix), (message, name)
    return message[len(prefix):]


def toml_literal(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return repr(value)


def cli_text(value):
    return value if isinstance(value, str) else repr(value)


# -- the run's scalar parameters: with a flag (--photons, --seed, --max-depth, --radius, --method) or -O --

FLAGGED = {  # parameter: (flag, scene file table.key, bad values, good values and what they read as)
    "photons": ("--photons", "photons.count",
                [0, -5, 2.5, math.inf, math.nan, "many", 3_000_000_000, 2**31 + 1],
                [(1, 1), (2000, 2000), (1e5, 100_000), (2**31, 2**31)]),
    "seed": ("--seed", "photons.seed",
             [-1, 2**64, 1.5, math.nan, "x"],
             [(0, 0), (1e3, 1000), (2**64 - 1, 2**64 - 1)]),
    "max_depth": ("--max-depth", "photons.max_depth",
                  [0, 257, 2.5, "deep"],
                  [(1, 1), (16.0, 16), (256, 256)]),
    # float32 edges: 1e-300 and 1e200 were a ZeroDivisionError and an
    # OverflowError, 1e-30 NaN everywhere (its square is 0 in float32)
    "radius": ("--radius", "estimator.radius",
               [0, -1, -0.5, math.inf, math.nan, "big", 1e-300, 1e-30, 1e-19, 1e200, 2e18],
               [(1e-18, 1e-18), (0.1, 0.1), (2, 2.0), (1e18, 1e18)]),
    "method": ("--method", "estimator.method",
               ["photonmap", "DETP", "", 5],
               [(m, m) for m in params.METHODS]),
}
# the parameters without a flag: -O extension=E, -O count_emitted=false
OPTION_PARAMS = {
    "extension": ("estimator.extension", [-1, -0.5, math.inf, math.nan, "x", 1e19],
                  [(0, 0.0), (0.5, 0.5), (1e18, 1e18)]),
    "count_emitted": ("estimator.count_emitted", [1, 0, 1.0, "yes"], [(True, True), (False, False)]),
}
BAD = [(p, v) for p, spec in FLAGGED.items() for v in spec[2]] + \
    [(p, v) for p, spec in OPTION_PARAMS.items() for v in spec[1]]
GOOD = [(p, v, want) for p, spec in FLAGGED.items() for v, want in spec[3]] + \
    [(p, v, want) for p, spec in OPTION_PARAMS.items() for v, want in spec[2]]


def _key_and_args(param, value, text):
    """The scene file's table.key of ``param`` and its command-line arguments
    (a flag's, or -O param=VALUE), ``value`` written by ``text``."""
    if param in FLAGGED:
        return FLAGGED[param][1], [FLAGGED[param][0], cli_text(value)]
    return OPTION_PARAMS[param][0], ["-O", f"{param}={text(value)}"]


@pytest.mark.parametrize("param, value", BAD, ids=[f"{p}={v!r}" for p, v in BAD])
def test_parameter_refused_alike(param, value, engine, cli_fails, tmp_path):
    key, args = _key_and_args(param, value, cli_text)
    write_scene(tmp_path)
    line = cli_fails(tmp_path, "render", "s.toml", "-o", "x.exr", *args)
    by_cli = (flag_problem(line, args[0]) if param in FLAGGED
              else named_problem(flag_problem(line, "-O/--option"), param))

    table, name = key.split(".")
    scene = write_scene(tmp_path / "bad", extra=f"[{table}]\n{name} = {toml_literal(value)}\n")
    with pytest.raises(params.ParamError) as info:
        load_file(scene)
    by_file = named_problem(str(info.value), key)
    assert cli_fails(tmp_path / "bad", "render", "s.toml", "-o", "x.exr") == f"oclgi: error: {key}: {by_file}"

    with pytest.raises(params.ParamError) as info:
        engine.run_params(**{param: value})
    by_api = named_problem(str(info.value), param)

    assert by_cli == by_file == by_api
    assert f"{value!r}" in by_api and (param in FLAGGED or by_api.endswith(f"got {value!r}"))


@pytest.mark.parametrize("param, value, want", GOOD, ids=[f"{p}={v!r}" for p, v, _ in GOOD])
def test_parameter_accepted_alike(param, value, want, engine, tmp_path):
    key, args = _key_and_args(param, value, toml_literal)
    parsed = build_parser().parse_args(["render", "s.toml", *args])
    table, name = key.split(".")
    scene = load_file(write_scene(tmp_path, extra=f"[{table}]\n{name} = {toml_literal(value)}\n"))
    api = engine.run_params(**{param: value})
    by_cli = getattr(parsed, param) if param in FLAGGED else dict(parsed.option)[param]
    for got in (by_cli, getattr(scene.settings, param), getattr(api, param)):
        assert got == want and type(got) is type(want)


def test_option_parameters_reach_the_run(tmp_path):
    """-O extension and -O count_emitted change the estimate as the API's arguments do."""
    write_scene(tmp_path)
    np.save(tmp_path / "p.npy", POINTS)
    res = run(tmp_path, "irradiance", "s.toml", "--points", "p.npy", "-o", "e.npy", "--photons", "2e3",
              "--quiet", "-O", "count_emitted=false", "-O", "extension=0.05")
    assert res.returncode == 0, res.stderr
    engine = oclgi.Engine(load_file(tmp_path / "s.toml"), progress=False)
    api = engine.irradiance(POINTS, photons=2000, count_emitted=False, extension=0.05).irradiance
    np.testing.assert_array_equal(np.load(tmp_path / "e.npy"), api)


# -- a method's own options ------------------------------------------------------------------------

@pytest.mark.parametrize("method, options", [
    ("detp", {"q": 0.5}),
    ("photon_map", {"q": 0.5, "leaf": 3}),
    ("detp_sphere_cache", {"k": 50}),
])
def test_unknown_option_refused_alike(method, options, engine, cli_fails, tmp_path):
    write_scene(tmp_path)
    args = [a for k, v in options.items() for a in ("-O", f"{k}={v}")]
    line = cli_fails(tmp_path, "render", "s.toml", "-o", "x.exr", "--photons", "100", "--method", method, *args)
    with pytest.raises(OclgiError) as info:
        engine.irradiance(POINTS, method=method, photons=100, **options)
    assert line == f"oclgi: error: {info.value}"
    assert f"method {method!r} takes no option(s) {sorted(options)}" in line
    with pytest.raises(OclgiError) as study:
        Config(method, [100], **options)
    assert str(study.value) == str(info.value)


@pytest.mark.parametrize("key", ["radius", "photons", "seed", "max_depth", "method", "local_size", "count_work"])
def test_run_parameter_is_no_option(key, engine, cli_fails, tmp_path):
    """-O radius=... was a TypeError traceback (the value came twice); local_size through
    the API's options too."""
    write_scene(tmp_path)
    line = cli_fails(tmp_path, "render", "s.toml", "-o", "x.exr", "-O", f"{key}=1")
    problem = f"{key} is a parameter of its own, not an option of a method"
    assert flag_problem(line, "-O/--option") == problem
    if key == "local_size":
        with pytest.raises(OclgiError, match=f"^{problem}$"):
            engine.irradiance(POINTS, photons=100, local_size=8)


def test_option_text():
    assert params.option_text("k=50") == ("k", 50) and params.option_text(" q = 0.6") == ("q", 0.6)
    assert params.option_text("front_only=false") == ("front_only", False)  # was the string 'false'
    assert params.option_text("front_only=True") == ("front_only", True)
    assert params.option_text("order=morton") == ("order", "morton")
    assert params.option_text("count_emitted=false") == ("count_emitted", False)
    for bad in ("k", "=3", "2k=3"):
        with pytest.raises(params.ParamError, match="expected KEY=VALUE"):
            params.option_text(bad)


def test_boolean_option_from_the_command_line(tmp_path):
    """-O front_only=false reaches the photon map as False (it was refused as 'false')."""
    write_scene(tmp_path)
    np.save(tmp_path / "p.npy", POINTS)
    res = run(tmp_path, "irradiance", "s.toml", "--points", "p.npy", "-o", "e.npy", "--photons", "2000",
              "--method", "photon_map", "-O", "k=5", "-O", "front_only=false", "--quiet")
    assert res.returncode == 0, res.stderr


# -- the study: its own names for the same readers ----------------------------------------------------

@pytest.mark.parametrize("args, api, problem", [
    (["--photons", "1000,0"], dict(photons=[1000, 0]),
     "expected photon counts (positive integers up to 2^31), got [1000, 0]"),
    (["--photons", "1000,2.5"], dict(photons=[1000, 2.5]),
     "expected photon counts (positive integers up to 2^31), got [1000, 2.5]"),
    (["--radius", "1e-30"], dict(photons=[1000], radius=1e-30),
     "expected a number from 1e-18 to 1e18 (the device squares it in float32), got 1e-30"),
    (["--methods", "detp,photonmap"], dict(method="photonmap", photons=[1000]),
     "unknown method 'photonmap'; choose one of " + ", ".join(params.METHODS)),
])
def test_study_refuses_alike(args, api, problem, cli_fails, tmp_path):
    write_scene(tmp_path)
    line = cli_fails(tmp_path, "study", "s.toml", "--seeds", "2", *args, "-o", "out")
    assert flag_problem(line, args[0]) == problem
    api.setdefault("method", "detp")
    with pytest.raises(params.ParamError) as info:
        Config(api.pop("method"), **api)
    assert info.value.problem == problem


def test_study_config_takes_the_run_options():
    c = Config("detp_disc_index", [2e3, 1000, 1e3], radius=0.1, extension=0.5, count_emitted=False, leaf_size=4)
    assert c.photons == (1000, 2000) and all(type(n) is int for n in c.photons)
    assert c.options == {"extension": 0.5, "count_emitted": False, "leaf_size": 4}
    with pytest.raises(params.ParamError, match=r"^count_emitted: expected true or false, got 1$"):
        Config("detp", [1000], count_emitted=1)


# -- emission and intensity the device cannot hold ------------------------------------------------------

@pytest.mark.parametrize("where, toml, value", [
    ("mesh[0].materials.light.emission", "[mesh.materials.light]\nemission = {v}\n", [1e39, 1, 1]),
    ("mesh[0].materials.light.emission", "[mesh.materials.light]\nemission = {v}\n", [1e-46, 0, 0]),
    ("mesh[0].emission", "emission = {v}\n", [0, 1e39, 0]),
    ("point_light[0].intensity", "", [1e39, 1, 1]),
    ("point_light[0].intensity", "", [1, 1e-46, 1]),
])
def test_emission_beyond_float32(where, toml, value, cli_fails, tmp_path):
    """Were ZeroDivisionError tracebacks (the photons' power rounds to 0 or inf)."""
    lit = "[" + ", ".join(repr(float(x)) if x else "0" for x in value) + "]"
    light = f"[[point_light]]\nposition = [0, 0.5, 0]\nintensity = {lit}\n" if "point_light" in where else ""
    scene = write_scene(tmp_path, mesh=toml.format(v=lit), extra=light)
    line = cli_fails(tmp_path, "render", "s.toml", "-o", "x.exr")
    message = (f"{where}: expected 3 numbers, each 0 or from 1.2e-38 to 3.4e38 (float32 on the device), "
               f"got {[float(x) if x else 0 for x in value]!r}")
    assert line == f"oclgi: error: {message}"
    with pytest.raises(OclgiError) as info:
        load_file(scene)
    assert str(info.value) == message
    # the dict form, as the API gives it
    desc = {"mesh": [{"path": str(tmp_path / "box.obj")}]}
    if "point_light" in where:
        desc["point_light"] = [{"position": [0, 0.5, 0], "intensity": value}]
    elif "materials" in where:
        desc["mesh"][0]["materials"] = {"light": {"emission": value}}
    else:
        desc["mesh"][0]["emission"] = value
    with pytest.raises(OclgiError, match=r"^" + re.escape(where) + r": expected 3 numbers, each 0 or from"):
        load_dict(desc)


def test_emission_in_mtl_beyond_float32(cli_fails, tmp_path):
    write_scene(tmp_path)
    (tmp_path / "box.mtl").write_text(MTL.replace("Ke 5 5 5", "Ke 1e39 5 5"))
    line = cli_fails(tmp_path, "render", "s.toml", "-o", "x.exr")
    assert line.startswith("oclgi: error: box.obj: material 'light' (Ke): expected 3 numbers, each 0 or from")


def test_dim_emitters_are_a_clear_error(tmp_path, cli_fails):
    """Emission float32 holds but too dim for float32 fixed-point sums: one clear line."""
    scene = write_scene(tmp_path, mesh="[mesh.materials.light]\nemission = [1e-30, 0, 0]\n")
    line = cli_fails(tmp_path, "render", "s.toml", "-o", "x.exr", "--photons", "100")
    assert "the emitters' power" in line and "too small" in line
    engine = oclgi.Engine(load_file(scene), progress=False)
    with pytest.raises(OclgiError, match="too small for fixed-point sums of 100 paths"):
        engine.irradiance(POINTS, photons=100)


def test_emission_within_float32_is_fine(engine, tmp_path):
    scene = load_file(write_scene(tmp_path, mesh="[mesh.materials.light]\nemission = [1e30, 0, 1.2e-38]\n"))
    assert max(m.emission[0] for m in scene.materials) == 1e30


# -- RunParams: the one dataclass of a run's parameters ---------------------------------------------------

def test_run_params_dataclass(engine):
    p = engine.run_params()
    assert isinstance(p, params.RunParams) and isinstance(engine.scene.settings, params.RunParams)
    assert p.radius == pytest.approx(engine.scene.radius) and engine.scene.settings.radius is None
    assert params.RunParams(photons=1e3, seed=2.0).photons == 1000
    with pytest.raises(params.ParamError, match=r"^photons: expected a positive integer up to 2\^31, got 0$"):
        params.RunParams(photons=0)
    with pytest.raises(Exception):
        p.photons = 5  # frozen: change one with dataclasses.replace, which checks again
    with pytest.raises(params.ParamError, match="^max_depth: "):
        dataclasses.replace(p, max_depth=0)
    with pytest.raises(OclgiError, match="settings must be an oclgi.params.RunParams"):
        oclgi.Scene(engine.scene.vertices, engine.scene.faces, engine.scene.tri_material, engine.scene.materials,
                    settings={"photons": 10})


def test_trace_checks_its_parameters(engine):
    for kwargs, name in ((dict(photons=0), "photons"), (dict(seed=-1), "seed"), (dict(max_depth=300), "max_depth")):
        with pytest.raises(params.ParamError, match=f"^{name}: expected"):
            engine.trace(**kwargs)
    segments, lengths = engine.trace(photons=1e2, seed=3.0, max_depth=4)
    assert len(lengths) == 100


def test_readers_never_round():
    assert params.photons(np.int64(7)) == 7 and params.seed(np.uint64(2**64 - 1)) == 2**64 - 1
    for reader in (params.photons, params.seed, params.max_depth):
        for bad in (True, np.bool_(True), 2.5, np.float32(2.5), "3", None, [3]):
            with pytest.raises(params.ParamError):
                reader(bad)
    assert params.radius(np.float32(0.25)) == 0.25  # was refused: not a Python float
    with pytest.raises(params.ParamError, match=r"^radius: .*got True$"):
        params.radius(True)  # was a radius of 1.0
    with pytest.raises(params.ParamError, match=r"^radius: expected a number"):
        params.radius(10**400)  # beyond float's range


def test_cli_subprocess_float32_radius(tmp_path):
    """The command as users run it: one line, exit 2, no traceback (was ZeroDivisionError)."""
    write_scene(tmp_path)
    res = run(tmp_path, "render", "s.toml", "-o", "x.exr", "--radius", "1e-300")
    assert isinstance(res, subprocess.CompletedProcess)
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.strip() == ("oclgi: error: argument --radius: expected a number from 1e-18 to 1e18 "
                                  "(the device squares it in float32), got 1e-300 (see `oclgi render --help`)")
    assert not (tmp_path / "x.exr").exists()


# -- readers of the API's other numbers: float32 values, image sizes, exposure, frames, seeds ----------

@pytest.mark.parametrize("value", [3.5e38, -3.5e38, 1e-39, -1e-45, math.nan, math.inf, True, "1", None, 10**400])
def test_float32_real_refuses_what_float32_cannot_hold(value):
    with pytest.raises(params.ParamError, match=r"^emission: expected a number from -3.4e38 to 3.4e38, 0 or at "
                                                r"least 1.2e-38 in size \(float32 on the device\), got"):
        params.float32_real(value, "emission")


def test_float32_real_accepts_and_bounds():
    assert params.float32_real(0, "x") == 0.0 and params.float32_real(np.float32(2.5), "x") == 2.5
    assert params.float32_real(3.4e38, "x") == 3.4e38 and params.float32_real(-1.2e-38, "x") == -1.2e-38
    with pytest.raises(params.ParamError, match=r"^x: expected a number from 0 to 1, 0 or at least"):
        params.float32_real(-0.5, "x", 0.0, 1.0)


@pytest.mark.parametrize("reader, bad, good", [
    (params.image_size, [0, -1, 16385, 2.5, True, math.nan, "8"], [(1, 1), (16384, 16384), (np.int64(7), 7), (64.0, 64)]),
    (params.exposure, [0, -1, math.nan, math.inf, 1e-39, 1e39, False, "2"], [(1, 1.0), (np.float32(0.5), 0.5)]),
    (params.frames, [0, -3, 1.5, True, 10**6 + 1], [(1, 1), (1e6, 10**6), (np.int32(30), 30)]),
    (params.seed_count, [1, 0, 2.5, True, 2**40 + 1], [(2, 2), (1e3, 1000)]),
    (params.flag, [0, 1, "true", None], [(True, True), (np.bool_(False), False)]),
    (params.local_size, [0, -1, 2.5, True], [(64, 64), (np.int64(8), 8)]),
])
def test_api_readers(reader, bad, good):
    for value in bad:
        with pytest.raises(params.ParamError, match=r"^p: expected "):
            reader(value, "p")
    for value, read in good:
        got = reader(value, "p")
        assert got == read and type(got) is type(read)


def test_huge_frame_count_gives_its_memory():
    for value in (10**8, 1e8):
        with pytest.raises(params.ParamError, match=r"^--frames: expected an integer in 1..1,000,000, got 100000000 "
                                                    r"\(its poses and timings alone would take about 119.2 GiB"):
            budget.frames(value, "--frames")
    assert budget.frames(np.int64(30), "--frames") == 30


@pytest.mark.parametrize("seed", [2**53, 2**53 + 1, 2**63 - 1, 2**64 - 1])
def test_scene_file_seeds_beyond_2_53_are_exact(seed, tmp_path, engine):
    """TOML integers are exact: a seed the command line takes, the scene file takes, to the last bit."""
    scene = load_file(write_scene(tmp_path, extra=f"[photons]\nseed = {seed}\n"))
    assert scene.settings.seed == seed and type(scene.settings.seed) is int
    assert params.seed(str(seed) and params.number_text(str(seed)), "--seed") == seed
    assert engine.run_params(seed=seed).seed == seed
