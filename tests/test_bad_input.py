"""Bad input: one clear line, exit status 2, no traceback, no output file.

Every case runs the command line on a tiny scene written into tmp_path and
checks that

* stderr holds exactly one ``oclgi: error: ...`` line (warning lines may
  precede it) and no traceback; nothing is printed on stdout;
* the exit status is 2;
* no file was created anywhere under tmp_path: no output, no temporary file.

The cases the command line must handle run ``python -m oclgi`` in a
subprocess (``SUB``); their many variants call ``oclgi.cli.main`` in-process
(same code, same checks, without an interpreter start each), where an
uncaught exception fails the test just as a traceback would.
"""

import os
import zipfile

import numpy as np
import pytest
from cli_run import run
from small_scene import BOX_MTL, BOX_OBJ, POINTS, write_scene

from oclgi import io
from oclgi.errors import OclgiError

SUB = True  # run this case in a subprocess
INP = False  # run it in-process
RENDER = ("render", "s.toml", "-o", "out/x.exr")


@pytest.fixture
def scene(tmp_path):
    return write_scene(tmp_path)


# -- scene files ----------------------------------------------------------------

@pytest.mark.parametrize("sub, make, name, match", [
    (SUB, lambda d: None, "nope.toml", r"scene file not found: nope\.toml"),  # missing
    (INP, lambda d: (d / "d.toml").mkdir(), "d.toml", "scene file not found"),  # a folder
    (INP, lambda d: (d / "s.toml").write_bytes(b"\xff\xfe\x00garbage"), "s.toml", "not a text"),  # binary
])
def test_unreadable_scene_file(cli_fails, tmp_path, sub, make, name, match):
    make(tmp_path)
    cli_fails(tmp_path, "render", name, "-o", "out/x.exr", match=match, sub=sub)


MESH = "[[mesh]]\npath = 'box.obj'\n"
# an emitting triangle, given its vertices 1 and 2 and the last index of its face
TRIANGLE = "[[mesh]]\nvertices = [[0, 0, 0], {}]\nfaces = [[0, 1, {}]]\nemission = [1, 1, 1]\n"


@pytest.mark.parametrize("sub, toml, match", [
    (SUB, "[[mesh]\npath = 'box.obj'\n", r"s\.toml: malformed TOML.*line 1"),
    # deeply nested: was a RecursionError's traceback
    (SUB, "a = " + "[" * 1000 + "]" * 1000 + "\n", r"s\.toml: malformed TOML: .*nested too deeply"),
    (SUB, "a = " + "{b = " * 1000 + "1" + "}" * 1000 + "\n", r"s\.toml: malformed TOML: .*nested too deeply"),
    (SUB, "mesh = 5\n", r"mesh: expected \[\[mesh\]\]"),
    (INP, "[[mesh]]\npath = 5\n", r"mesh\[0\]\.path: expected a file name"),
    (INP, MESH + "materials = 5\n", r"mesh\[0\]\.materials"),
    (INP, MESH + "albedo = '123'\n", r"mesh\[0\]\.albedo: expected 3 numbers"),
    (INP, MESH + "albedo = [true, 0, 0]\n", r"mesh\[0\]\.albedo: expected 3 numbers"),
    (INP, MESH + "albedo = [2, 0, 0]\n", r"albedo must be 3 numbers in \[0, 1\]"),
    (INP, MESH + "colour = [1, 0, 0]\n", r"unknown key\(s\) \['colour'\]"),
    (INP, MESH + "[mesh.materials.nosuch]\nemission = [1, 1, 1]\n", r"\['nosuch'\] not in the mesh's materials"),
    (INP, TRIANGLE.format("[1, 0, 0], [0, 1, 'a']", 2), r"mesh\[0\]\.vertices: expected numbers"),
    (INP, TRIANGLE.format("[1, 0, 0], [0, 1]", 2), r"mesh\[0\]\.vertices"),
    (INP, TRIANGLE.format("[1, 0, 0], [0, 1, 0]", 2.5), r"mesh\[0\]\.faces: indices must be integers"),
    (INP, TRIANGLE.format("[1, 0, 0], [0, 1, 0]", 3), r"mesh\[0\]: face indices out of range"),
    (INP, TRIANGLE.format("[1, 0, nan], [0, 1, 0]", 2), r"mesh\[0\]: 1 vertices have NaN or infinite"),
    (INP, MESH + "transform = {scale = 1e30}\n", r"coordinates reach 1e\+30"),
    (INP, MESH + "[camera]\nposition = [0, 0, 1]\nlook_at = [0, 0, 1]\n", r"camera: look_at must differ"),
    (INP, MESH + "[camera]\nposition = [0, 0, 1]\nlook_at = [0, 0, 0]\nwidth = 1e400\n",
     r"camera\.width: expected a finite number"),
    (INP, MESH + "[estimator]\nmethod = 'photonmap'\n", r"unknown method 'photonmap'"),
    (INP, MESH + "[[point_light]]\nposition = [0, 1, 0]\n", r"point_light\[0\]\.intensity"),
])
def test_malformed_scene_structure(cli_fails, sub, tmp_path, toml, match):
    write_scene(tmp_path)
    (tmp_path / "s.toml").write_text(toml)
    cli_fails(tmp_path, *RENDER, match=match, sub=sub)


# -- mesh files -----------------------------------------------------------------

@pytest.mark.parametrize("sub, mesh, match", [(SUB, "nowhere.obj", r"mesh file not found: .*nowhere\.obj"),
                                             (INP, "box.fbx", r"unsupported mesh type '\.fbx'")])
def test_mesh_file_missing_or_of_no_known_type(cli_fails, tmp_path, sub, mesh, match):
    write_scene(tmp_path, mesh=mesh)
    if mesh.endswith(".fbx"):
        (tmp_path / mesh).write_text("whatever")
    cli_fails(tmp_path, *RENDER, match=match, sub=sub)


@pytest.mark.parametrize("sub, old, new, match", [
    (SUB, "v 1 0 -1\n", "v 1 2 x\n", r"box\.obj:3: malformed number in '1 2 x'"),
    (INP, "v 1 0 -1\n", "v 1 0\n", r"box\.obj:3: expected 3 numbers"),
    (SUB, "f 5 6 7 8\n", "f 5 6 7 9\n", r"box\.obj:13: face index '9' refers to no vertex"),
    (SUB, "f 5 6 7 8\n", "f 5 6 7 0\n", r"box\.obj:13: face index '0' refers to no vertex"),
    (INP, "f 5 6 7 8\n", "f -9 6 7\n", r"box\.obj:13: face index '-9' refers to no vertex"),
    (INP, "f 5 6 7 8\n", "f 5 6 x\n", r"box\.obj:13: malformed face index 'x'"),
    (SUB, "v 1 0 -1\n", "v nan 0 -1\n", r"box\.obj:3: vertex coordinate is NaN or infinite"),
    (SUB, "v 1 0 -1\n", "v inf 0 -1\n", r"box\.obj:3: vertex coordinate is NaN or infinite"),
    (SUB, "v 1 0 -1\n", "v 1 -inf -1\n", r"box\.obj:3: vertex coordinate is NaN or infinite"),
    # Python's int() and float() read "0_8" as 8 and "1_0" as 10
    (SUB, "f 5 6 7 8\n", "f 5 6 7 0_8\n", r"box\.obj:13: malformed face index '0_8'"),
    (INP, "v 1 0 -1\n", "v 1_0 0 -1\n", r"box\.obj:3: malformed number in '1_0 0 -1'"),
    (INP, "v 1 0 -1\n", "v \u0661 0 -1\n", r"box\.obj:3: malformed number"),  # an Arabic-Indic 1
])
def test_malformed_obj(cli_fails, sub, tmp_path, old, new, match):
    assert old in BOX_OBJ
    write_scene(tmp_path, obj=BOX_OBJ.replace(old, new, 1))
    cli_fails(tmp_path, *RENDER, match=match, sub=sub)


@pytest.mark.parametrize("sub, ke, match", [
    (INP, "Ke 5 five 5", r"box\.mtl:5: malformed number"),
    (INP, "Ke 5 -5 5", r"emission must be 3 numbers >= 0"),
    (SUB, "Ke 0 0 0", "the scene has no emitter"),
])
def test_bad_emission_in_mtl(cli_fails, sub, tmp_path, ke, match):
    write_scene(tmp_path, mtl=BOX_MTL.replace("Ke 5 5 5", ke))
    cli_fails(tmp_path, *RENDER, match=match, sub=sub)


PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 1\nproperty list uchar int vertex_indices\nend_header\n")


@pytest.mark.parametrize("sub, data, match", [
    (SUB, bytes(range(256)) * 4, r"m\.ply: cannot read PLY file"),
    (INP, b"", r"m\.ply: cannot read PLY file"),
    (INP, b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n", r"m\.ply: cannot read PLY file"),
    (INP, b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\n"
     b"property float z\nend_header\n\x00\x01", r"m\.ply: cannot read PLY file"),
    (INP, (PLY_HEAD + "0 0 0\nnan 1 0\n0 1 0\n3 0 1 2\n").encode(), r"m\.ply: 1 vertices have NaN or infinite"),
    (INP, (PLY_HEAD + "0 0 0\n1 1 0\n0 1 0\n3 0 1 7\n").encode(), r"m\.ply: face indices out of range"),
    (INP, (PLY_HEAD + "0 0 0\n1 1 0\n0 1 0\n3 0 1 -1\n").encode(), r"m\.ply: face indices out of range"),
])
def test_malformed_ply(cli_fails, sub, tmp_path, data, match):
    write_scene(tmp_path, mesh="m.ply", mesh_keys="emission = [1, 1, 1]\n")
    (tmp_path / "m.ply").write_bytes(data)
    cli_fails(tmp_path, *RENDER, match=match, sub=sub)


@pytest.mark.parametrize("members, match", [
    (None, r"m\.zip: not a readable zip file"),
    ({"a.obj": BOX_OBJ, "b.obj": BOX_OBJ}, "expected exactly one mesh file inside, found 2"),
    ({"inner.obj": BOX_OBJ.replace("v 1 0 -1\n", "v 1 0 q\n")}, r"m\.zip.inner\.obj:3: malformed number"),
])
def test_malformed_zip(cli_fails, tmp_path, members, match):
    write_scene(tmp_path, mesh="m.zip")
    if members is None:
        (tmp_path / "m.zip").write_bytes(b"PK\x03\x04 not really a zip")
    else:
        with zipfile.ZipFile(tmp_path / "m.zip", "w") as z:
            for name, text in members.items():
                z.writestr(name, text)
    cli_fails(tmp_path, *RENDER, match=match, sub=INP)


# -- emitters, degenerate triangles ---------------------------------------------------

def test_no_emitter_point_light_of_zero_intensity(cli_fails, tmp_path):
    write_scene(tmp_path, mtl=BOX_MTL.replace("Ke 5 5 5", ""),
                extra="\n[[point_light]]\nposition = [0, 1, 0]\nintensity = [0, 0, 0]\n")
    cli_fails(tmp_path, *RENDER, match="the scene has no emitter", sub=INP)


def test_missing_mtl_warns_then_no_emitter(tmp_path):
    write_scene(tmp_path, mtl=None)
    res = run(tmp_path, *RENDER)
    assert res.returncode == 2 and "Traceback" not in res.stderr
    lines = res.stderr.splitlines()
    assert len(lines) == 2, res.stderr
    assert lines[0].startswith("oclgi: warning: ") and "material library 'box.mtl' not found" in lines[0]
    assert lines[1].startswith("oclgi: error: ") and "no emitter" in lines[1]
    assert not (tmp_path / "out").exists()


def test_all_triangles_degenerate(cli_fails, tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n"
    write_scene(tmp_path, obj=obj, mtl=None, mesh_keys="emission = [1, 1, 1]\n")
    assert "dropped" not in cli_fails(tmp_path, *RENDER, match="every triangle is degenerate", sub=SUB)


def test_degenerate_triangles_dropped_with_warning(tmp_path):
    extra = "v 0 0 0\nv 0 0 0\nf 9 10 1\nf 1 1 2\nf 1 2 3\nf 2 9 3\n"  # 2 degenerate, 2 fine
    write_scene(tmp_path, obj=BOX_OBJ + extra)
    res = run(tmp_path, *RENDER, "--quiet")
    assert res.returncode == 0, res.stderr
    warn = [line for line in res.stderr.splitlines() if "degenerate" in line]
    assert len(warn) == 1 and warn[0].startswith("oclgi: warning: "), res.stderr
    assert "dropped 2 degenerate triangles" in warn[0]
    assert (tmp_path / "out" / "x.exr").is_file() and (tmp_path / "out" / "x.png").is_file()


# -- photon count, radius and other numbers --------------------------------------------

COUNT = r"photons\.count: expected a positive integer"
RADIUS = r"estimator\.radius: expected a number from 1e-18 to 1e18"


@pytest.mark.parametrize("sub, key, value, match", [
    (SUB, "count", "0", COUNT + r" up to 2\^31, got 0$"),
    (SUB, "count", "-5", COUNT + r" up to 2\^31, got -5$"),
    *[(INP, "count", v, COUNT) for v in ("2.5", "inf", "nan", "1e400", "'many'", "true")],
    (INP, "count", "3000000000", r"up to 2\^31"),
    (SUB, "radius", "0", RADIUS),
    (SUB, "radius", "-1", RADIUS),
    *[(INP, "radius", v, RADIUS) for v in ("-0.5", "inf", "nan")],
    (INP, "radius", "'big'", r"estimator\.radius: expected a number"),
])
def test_bad_count_or_radius_in_toml(cli_fails, sub, tmp_path, key, value, match):
    write_scene(tmp_path, **{key: value})
    cli_fails(tmp_path, *RENDER, match=match, sub=sub)


@pytest.mark.parametrize("sub, args, match", [
    (SUB, ["--photons", "0"], r"argument --photons: expected a positive integer up to 2\^31, got 0 "),
    (INP, ["--photons", "2.5e0"], r"argument --photons"),  # was silently truncated to 2
    (INP, ["--photons", "1e400"], r"argument --photons"),  # was a traceback
    (INP, ["--photons", "99999999999"], r"up to 2\^31"),
    (SUB, ["--radius", "-1"], r"argument --radius: expected a number from 1e-18 to 1e18 .*, got -1 "),
    (INP, ["--radius", "1e400"], r"argument --radius"),
    (INP, ["--max-depth", "1000"], r"argument --max-depth: expected an integer in 1\.\.256"),  # was accepted
    (INP, ["--seed", str(2**64)], r"argument --seed"),  # was a traceback
    (INP, ["--width", "0"], r"argument --width"),
    (INP, ["--width", "100000"], r"argument --width: expected an integer in 1\.\.16384"),
    (INP, ["--method", "photonmap"], r"argument --method: unknown method 'photonmap'"),
    (INP, ["--device", "no-such-device-anywhere"], r"no OpenCL device matches"),
    (INP, ["--bogus"], r"unrecognized arguments: --bogus"),
    (INP, ["--local-size", "1000000"], r"--local-size 1000000 is larger than"),
])
def test_bad_cli_numbers(cli_fails, sub, scene, tmp_path, args, match):
    cli_fails(tmp_path, *RENDER, *args, match=match, sub=sub)


def test_no_command(cli_fails, tmp_path):
    cli_fails(tmp_path, match=r"required: command", sub=SUB)


# -- outputs --------------------------------------------------------------------------

@pytest.mark.parametrize("out, match", [("out/x.jpg", r"must end in \.exr or \.png"),
                                        ("out/x", r"must end in \.exr or \.png")])
def test_bad_render_output_name(cli_fails, scene, tmp_path, out, match):
    cli_fails(tmp_path, "render", "s.toml", "-o", out, match=match, sub=INP)


def test_render_output_is_a_folder(cli_fails, scene, tmp_path):
    (tmp_path / "out" / "x.png").mkdir(parents=True)  # the PNG cannot be written: no EXR either
    cli_fails(tmp_path, *RENDER, match=r"x\.png: it is a folder", sub=SUB)
    assert os.listdir(tmp_path / "out") == ["x.png"]


def test_render_output_parent_is_a_file(cli_fails, scene, tmp_path):
    (tmp_path / "out").write_text("")
    cli_fails(tmp_path, *RENDER, match="is not a folder", sub=INP)


# -- points files and outputs of `oclgi irradiance` ------------------------------------------

@pytest.mark.parametrize("make, points, out, match", [
    (lambda d: (d / "e.npy").mkdir(), "p.csv", "e.npy", "it is a folder"),
    (lambda d: None, "p.csv", "e.txt", r"must end in \.npy or \.csv"),
    (lambda d: None, "nope.csv", "e.npy", r"points file not found: nope\.csv"),
    (lambda d: (d / "p.txt").write_text(POINTS), "p.txt", "e.npy", r"points must be a \.npy or \.csv file"),
    (lambda d: (d / "p.csv").write_bytes(b"\xff\xfe\x00\x01"), "p.csv", "e.npy", "not a text"),
])
def test_bad_irradiance_files(cli_fails, scene, tmp_path, make, points, out, match):
    make(tmp_path)
    cli_fails(tmp_path, "irradiance", "s.toml", "--points", points, "-o", out, match=match, sub=INP)


@pytest.mark.parametrize("sub, text, match", [
    (SUB, "nan,0.01,0,0,1,0\n", r"query point 0 has a NaN or infinite coordinate"),
    (INP, "0,0.01,0,0,1,0\n0,inf,0,0,1,0\n", r"query point 1 has a NaN or infinite coordinate"),
    (SUB, "0,0.01,0,0,0,0\n", r"query point 0 has a zero, NaN or infinite normal"),
    (INP, "0,0.01,0,0,nan,0\n", r"query point 0 has a zero, NaN or infinite normal"),
    (SUB, "0,0.01,0,0,1\n", r"p\.csv:1: expected 6 columns .*got 5"),
    (INP, "0,0.01,0,0,1,0,7\n", r"p\.csv:1: expected 6 columns .*got 7"),
    (INP, "x,y,z,nx,ny,nz\n0,0.01,0,0,1,0\n0,0.01,0,0,1\n", r"p\.csv:3: expected 6 columns .*got 5"),
    (INP, "0,0.01,0,0,1,0\n0,0.01,zero,0,1,0\n", r"p\.csv:2: expected 6 numbers"),
    (INP, "0,0.01,zero,0,1,0\n", r"p\.csv:1: expected 6 numbers"),
    (INP, "x,y,z,nx,ny,nz\n", r"p\.csv: no points"),
    (INP, "", r"p\.csv: no points"),
])
def test_bad_points_csv(cli_fails, sub, scene, tmp_path, text, match):
    (tmp_path / "p.csv").write_text(text)
    cli_fails(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", "e.csv", match=match, sub=sub)


def _npy(tmp_path, array, **kw):
    np.save(tmp_path / "p.npy", array, **kw)


@pytest.mark.parametrize("sub, make, match", [
    (INP, lambda d: _npy(d, np.array([[np.nan, 0.01, 0, 0, 1, 0]])), r"query point 0 has a NaN"),
    (INP, lambda d: _npy(d, np.array([[0, 0.01, 0, 0, 0, 0.0]])), r"query point 0 has a zero"),
    (INP, lambda d: _npy(d, np.zeros((2, 5))), r"expected n rows of 6 columns .*\(2, 5\)"),
    (INP, lambda d: _npy(d, np.zeros(6)), r"expected n rows of 6 columns .*\(6,\)"),
    (INP, lambda d: _npy(d, np.zeros((0, 6))), r"p\.npy: no points"),
    (INP, lambda d: _npy(d, np.array([["a"] * 6])), r"p\.npy: expected points as numbers, got an array of <U1"),
    (INP, lambda d: _npy(d, np.array([[0, 0.01, 0, 0, 1, 0]], dtype=object), allow_pickle=True),
     r"p\.npy: expected points as numbers, got an array of object"),
    (INP, lambda d: (d / "p.npy").write_bytes(bytes(range(200))), r"p\.npy: not a \.npy file"),
])
def test_bad_points_npy(cli_fails, sub, scene, tmp_path, make, match):
    make(tmp_path)
    cli_fails(tmp_path, "irradiance", "s.toml", "--points", "p.npy", "-o", "e.npy", match=match, sub=sub)


# -- the writers themselves: all or nothing, no temporary files, normal permissions ----------

def test_write_images_all_or_nothing(tmp_path, monkeypatch):
    real = io.write_image_file

    def fail_on_png(tmp, path, pixels, *args):
        if path.suffix == ".png":
            raise OclgiError(f"cannot write {path}: disk full")
        real(tmp, path, pixels, *args)

    monkeypatch.setattr(io, "write_image_file", fail_on_png)
    img = np.ones((2, 3, 3), np.float32)
    with pytest.raises(OclgiError, match="disk full"):
        io.write_images({tmp_path / "x.exr": img, tmp_path / "x.png": (img * 255).astype(np.uint8)})
    assert list(tmp_path.iterdir()) == []


def test_write_array_interrupted_leaves_nothing(tmp_path, monkeypatch):
    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "save", boom)
    with pytest.raises(KeyboardInterrupt):
        io.write_array(tmp_path / "e.npy", np.zeros((2, 3)))
    assert list(tmp_path.iterdir()) == []


def test_outputs_get_normal_permissions(tmp_path):
    mask = os.umask(0o022)
    try:
        p = io.write_array(tmp_path / "e.npy", np.zeros((2, 3)))
        q = io.write_image(tmp_path / "x.exr", np.zeros((2, 2, 3), np.float32))
    finally:
        os.umask(mask)
    assert p.stat().st_mode & 0o777 == 0o644  # mkstemp alone gives 0600
    assert q.stat().st_mode & 0o777 == 0o644
    assert sorted(f.name for f in tmp_path.iterdir()) == ["e.npy", "x.exr"]


def test_write_error_is_an_oclgi_error(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(OclgiError, match="is not a folder"):
        io.write_array(tmp_path / "f" / "e.npy", np.zeros((2, 3)))
