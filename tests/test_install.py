"""A non-editable install ships the kernels and finds them.

The package is built from a copy of the source (so the source tree gets no
``build/`` folder) and installed with ``pip install --target``; a fresh
interpreter with only that folder on its path, run from elsewhere, must
import oclgi from there, find every ``.cl`` and ``.h`` of ``kernels/`` in the
installed ``oclgi/kernels`` and build a program from it.
"""

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ("pyproject.toml", "setup.cfg", "README.md", "oclgi", "kernels")


def _can_build_offline() -> bool:
    """setuptools can build a wheel without fetching anything (bdist_wheel available)."""
    probe = ("import setuptools\n"
             "try:\n    import setuptools.command.bdist_wheel\nexcept ImportError:\n    import wheel.bdist_wheel\n")
    return subprocess.run([sys.executable, "-c", probe], capture_output=True).returncode == 0


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    base = tmp_path_factory.mktemp("install")
    src, target = base / "src", base / "target"
    src.mkdir()
    for name in SOURCES:
        p = ROOT / name
        if p.is_dir():
            shutil.copytree(p, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(p, src / name)
    cmd = [sys.executable, "-m", "pip", "install", "--no-deps", "--no-compile", "--quiet",
           "--disable-pip-version-check", "--target", str(target), str(src)]
    if _can_build_offline():
        cmd.insert(4, "--no-build-isolation")
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    return target


def _run_installed(target, cwd, code=None, args=None):
    """Python ``code`` (or the command ``args``) with only the installed copy importable."""
    env = {k: v for k, v in os.environ.items() if k not in ("OCLGI_KERNEL_DIR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(target)
    cmd = args if args is not None else [sys.executable, "-c", textwrap.dedent(code)]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def test_installed_package_finds_and_builds_kernels(installed, tmp_path):
    # An irradiance estimate builds photon_trace.cl (bvh.h, geometry.h, rng.h with pyopencl's
    # Random123, oclgi_types.h) and detp.cl (detp.h) from the installed folder.
    res = _run_installed(installed, tmp_path, """
        import json
        from pathlib import Path
        import oclgi
        from oclgi.cl.programs import kernel_dir, programs

        scene = oclgi.load_dict({"mesh": [
            {"vertices": [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], "faces": [[0, 2, 1], [0, 3, 2]]},
            {"vertices": [[-0.2, 1, -0.2], [0.2, 1, -0.2], [0.2, 1, 0.2]], "faces": [[0, 1, 2]],
             "emission": [1, 1, 1]}]})
        engine = oclgi.Engine(scene, progress=False)
        est = engine.irradiance([[0, 0.01, 0, 0, 1, 0]], photons=1000, radius=0.2)
        d = kernel_dir()
        print(json.dumps({
            "oclgi": str(Path(oclgi.__file__).resolve()),
            "kernel_dir": str(d.resolve()),
            "program_dir": str(programs(engine.ctx).dir.resolve()),
            "files": sorted(p.name for p in d.iterdir() if p.suffix in (".cl", ".h")),
            "irradiance": est.irradiance.tolist(),
        }))
    """)
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout.strip().splitlines()[-1])
    target = installed.resolve()
    assert Path(info["oclgi"]).is_relative_to(target), info["oclgi"]
    assert Path(info["kernel_dir"]).is_relative_to(target), info["kernel_dir"]
    assert info["program_dir"] == info["kernel_dir"]
    wanted = sorted(p.name for p in (ROOT / "kernels").iterdir() if p.suffix in (".cl", ".h"))
    assert wanted and info["files"] == wanted
    # the installed copies are the repository's files
    for name in wanted:
        assert (Path(info["kernel_dir"]) / name).read_bytes() == (ROOT / "kernels" / name).read_bytes(), name
    e = info["irradiance"]
    assert len(e) == 1 and len(e[0]) == 3 and all(v > 0 for v in e[0])


def test_installed_command_line(installed, tmp_path):
    """The installed console script and ``python -m oclgi`` run from the installed copy."""
    script = installed / "bin" / "oclgi"
    assert script.is_file()
    res = _run_installed(installed, tmp_path, args=[str(script), "info"])
    assert res.returncode == 0, res.stderr
    assert res.stdout.lstrip().startswith(("* ", "  "))
    res = _run_installed(installed, tmp_path, args=[sys.executable, "-m", "oclgi", "render", "missing.toml"])
    assert res.returncode == 2 and res.stderr.strip() == "oclgi: error: scene file not found: missing.toml"


def test_installed_package_ships_the_viewer_page(installed):
    """``oclgi view``'s page (index.html, its script and style) is package data."""
    static = ROOT / "oclgi" / "viewer" / "static"
    wanted = sorted(p.name for p in static.iterdir())
    assert {"index.html", "viewer.js", "viewer.css"} <= set(wanted)
    shipped = installed / "oclgi" / "viewer" / "static"
    assert sorted(p.name for p in shipped.iterdir()) == wanted
    for name in wanted:
        assert (shipped / name).read_bytes() == (static / name).read_bytes(), name
