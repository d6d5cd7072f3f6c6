"""The ``oclgi`` command line, successful runs (bad input: test_bad_input.py).

Each run is ``python -m oclgi`` in a subprocess, on a tiny scene written
into tmp_path (2,000 photons, an 8 x 8 camera), about a second each.
"""

import os
import re
from importlib.metadata import entry_points

import numpy as np
import pytest
from cli_run import run
from small_scene import write_scene

from oclgi.io import read_image

# A floor quad and a small quad light above it facing down; the light's
# emission comes from the TOML (materials.light), the floor's albedo from Kd.
BOX_MTL = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl light\nKd 0 0 0\n"
LAMP = "[[point_light]]\nposition = [0.5, 0.8, 0.5]\nintensity = [0.2, 0.1, 0.05]\n"
POINTS = [[0, 0.01, 0, 0, 1, 0], [0.5, 0.01, 0.5, 0, 1, 0], [-0.7, 0.01, 0.3, 0, 2, 0], [0, 0.5, 0, 1, 0, 0]]


def ok(res):
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    return res


@pytest.fixture
def scene(tmp_path):
    """small_scene's scene (8 x 8, 2,000 photons, radius 0.1), seed 7, the light's emission and LAMP."""
    return write_scene(tmp_path, mtl=BOX_MTL, mesh_keys="[mesh.materials.light]\nemission = [5, 5, 5]\n",
                       photon_keys="seed = 7\n", extra=LAMP)


def _check_image_pair(exr, png, w, h):
    rad = read_image(exr)
    assert rad.shape == (h, w, 3) and rad.dtype == np.float32 and np.isfinite(rad).all() and (rad >= 0).all()
    assert rad.max() > 0  # the floor is lit and the light is in view
    pix = read_image(png)
    assert pix.shape[:2] == (h, w) and pix.shape[2] in (3, 4) and np.isfinite(pix).all() and (pix >= 0).all()


def test_render_writes_exr_and_png(scene, tmp_path):
    res = ok(run(tmp_path, "render", "s.toml", "-o", "imgs/x.exr", "--photons", "2000"))
    exr, png = tmp_path / "imgs" / "x.exr", tmp_path / "imgs" / "x.png"
    _check_image_pair(exr, png, 8, 8)
    # says where it wrote them, on stdout; the summary goes to stderr
    assert res.stdout.splitlines() == [f"wrote {os.path.join('imgs', 'x.exr')}", f"wrote {os.path.join('imgs', 'x.png')}"]
    assert re.search(r"2,000 photons", res.stderr)
    assert sorted(p.name for p in (tmp_path / "imgs").iterdir()) == ["x.exr", "x.png"]  # no temporary files
    mask = 0o777 & ~_umask()
    assert (exr.stat().st_mode & 0o777) == (0o666 & mask)


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_render_png_name_size_flags_and_default_output(scene, tmp_path):
    # -o with .png writes the same pair; --width/--height override the camera; --quiet prints no summary
    res = ok(run(tmp_path, "render", "s.toml", "-o", "y.png", "--width", "6", "--height", "4", "--quiet",
                 "--photons", "2e3", "--method", "impact"))
    _check_image_pair(tmp_path / "y.exr", tmp_path / "y.png", 6, 4)
    assert res.stderr == "" and res.stdout.split() == ["wrote", "y.exr", "wrote", "y.png"]
    # without -o: out/SCENE.exr under the working folder
    ok(run(tmp_path, "render", "s.toml", "--quiet"))
    _check_image_pair(tmp_path / "out" / "s.exr", tmp_path / "out" / "s.png", 8, 8)


def _csv_points(path, rows):
    path.write_text("x,y,z,nx,ny,nz\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")


def test_irradiance_csv_and_npy(scene, tmp_path):
    _csv_points(tmp_path / "p.csv", POINTS)
    np.save(tmp_path / "p.npy", np.array(POINTS, np.float64))

    res = ok(run(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", "e.csv"))
    assert res.stdout.strip() == "wrote e.csv"
    assert (tmp_path / "e.csv").read_text().splitlines()[0] == "x,y,z,nx,ny,nz,E_r,E_g,E_b"
    table = np.loadtxt(tmp_path / "e.csv", delimiter=",", skiprows=1)
    assert table.shape == (len(POINTS), 9)
    np.testing.assert_allclose(table[:, :3], np.array(POINTS)[:, :3], atol=1e-6)
    normals = np.array(POINTS, np.float64)[:, 3:]
    np.testing.assert_allclose(table[:, 3:6], normals / np.linalg.norm(normals, axis=1, keepdims=True), atol=1e-6)
    e_csv = table[:, 6:]

    ok(run(tmp_path, "irradiance", "s.toml", "--points", "p.npy", "-o", "e.npy", "--quiet"))
    e_npy = np.load(tmp_path / "e.npy")
    assert e_npy.shape == (len(POINTS), 3) and e_npy.dtype == np.float64
    for e in (e_csv, e_npy):
        assert np.isfinite(e).all() and (e >= 0).all()
        assert (e[:3].sum(axis=1) > 0).all()  # floor points under the light receive light
    # same scene, same seed: the same numbers whatever the points file format
    np.testing.assert_allclose(e_npy, e_csv, rtol=1e-6, atol=1e-9)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_irradiance_flags_change_the_estimate(scene, tmp_path):
    np.save(tmp_path / "p.npy", np.array(POINTS, np.float64))
    ok(run(tmp_path, "irradiance", "s.toml", "--points", "p.npy", "-o", "a.npy", "--quiet"))
    ok(run(tmp_path, "irradiance", "s.toml", "--points", "p.npy", "-o", "b.npy", "--quiet",
           "--seed", "8", "--radius", "0.2", "--max-depth", "3", "--local-size", "8"))
    a, b = np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy")
    assert a.shape == b.shape == (len(POINTS), 3) and np.isfinite(b).all() and (b >= 0).all()
    assert not np.array_equal(a, b)


def test_info_lists_a_device(tmp_path):
    res = ok(run(tmp_path, "info"))
    devices = [line for line in res.stdout.splitlines() if re.match(r"^[* ] \d+:\d+ ", line)]
    assert devices, res.stdout
    assert any(line.startswith("*") for line in devices)  # the default is marked


def test_help(tmp_path):
    res = ok(run(tmp_path, "--help"))
    for cmd in ("render", "irradiance", "info"):
        assert cmd in res.stdout
    res = ok(run(tmp_path, "render", "--help"))
    for flag in ("--photons", "--radius", "--method", "-o"):
        assert flag in res.stdout
    text = " ".join(res.stdout.split())  # and it names the sibling image (tests/test_outputs.py)
    assert "-o x.exr writes x.exr and x.png" in text
    assert "--no-png" in text and "--no-exr" in text and "--force" in text


def test_console_script_installed():
    """The ``oclgi`` entry point of the installed package runs the same main()."""
    eps = [ep for ep in entry_points(group="console_scripts") if ep.name == "oclgi"]
    assert eps and eps[0].value == "oclgi.cli:main"
