"""Small things a user reaches for: paths as pathlib.Path, inline images in
notebooks, the command's version."""

import pathlib
import tomllib

import numpy as np
from cli_run import in_process
from small_scene import MOVING_BLOCK

import oclgi
from oclgi.io import read_image


def test_a_mesh_path_may_be_a_pathlib_path(scenes_dir):
    as_str = oclgi.load_dict({"mesh": [{"path": str(scenes_dir / "cornell-box" / "CornellBox-Original.obj")}]})
    as_path = oclgi.load_dict({"mesh": [{"path": scenes_dir / "cornell-box" / "CornellBox-Original.obj"}]})
    assert np.array_equal(as_str.vertices, as_path.vertices) and np.array_equal(as_str.faces, as_path.faces)


def test_a_render_shows_inline_as_the_png_it_writes(tmp_path):
    engine = oclgi.Engine(oclgi.load_dict(tomllib.loads(MOVING_BLOCK)))
    result = engine.render(photons=5_000)
    png = result._repr_png_()
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    path = tmp_path / "inline.png"
    path.write_bytes(png)
    decoded = np.rint(read_image(path) * 255).astype(np.uint8)  # OpenImageIO reads it as floats in 0..1
    assert np.array_equal(decoded, result.pixels)


def test_version(tmp_path, monkeypatch, capsys):
    res = in_process(monkeypatch, capsys, tmp_path, "--version")
    assert res.returncode == 0 and res.stdout.strip() == f"oclgi {oclgi.__version__}"
