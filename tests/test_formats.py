"""Mesh and scene files read right or refused in plain words.

Degenerate triangles are judged each by its own shape (a huge ground plane
does not make a room's light "degenerate"); glTF with external buffers,
PLY/OFF whose counts lie, zip members that inflate past the limit, deeply
nested TOML and numbers beyond float32 are read or refused with one
OclgiError naming the file and the problem.
"""

import configparser
import struct
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
import trimesh

import oclgi
from oclgi.errors import OclgiError
from oclgi.scene import zip_reader
from oclgi.scene.degenerate import degenerate_triangles
from oclgi.scene.description import load_dict, load_file
from oclgi.scene.mesh import load_mesh
from oclgi.scene.scene import OclgiWarning
from oclgi.scene.trimesh_errors import PACKAGES

FLOOR = {"vertices": [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], "faces": [[0, 2, 1], [0, 3, 2]]}
# 0.4 m x 0.4 m: 0.16 m^2 in two triangles
LIGHT = {"vertices": [[-0.2, 1, -0.2], [0.2, 1, -0.2], [0.2, 1, 0.2], [-0.2, 1, 0.2]],
         "faces": [[0, 1, 2], [0, 2, 3]], "emission": [5, 5, 5]}
H = 1e5  # half of a 200 km ground plane
GROUND = {"vertices": [[-H, -0.1, -H], [H, -0.1, -H], [H, -0.1, H], [-H, -0.1, H]], "faces": [[0, 2, 1], [0, 3, 2]]}


# -- degenerate triangles ---------------------------------------------------------------

def test_huge_ground_plane_keeps_the_light():
    with warnings.catch_warnings():
        warnings.simplefilter("error", OclgiWarning)  # nothing is dropped
        scene = load_dict({"mesh": [FLOOR, LIGHT, GROUND]})
    assert scene.n_triangles == 6 and scene.has_emitter()
    assert np.isclose(scene.triangle_areas()[scene.tri_material == 1].sum(), 0.16)


def test_slivers_and_zero_area_triangles_still_dropped_beside_a_huge_plane():
    bad = {"vertices": [[0, 0.5, 0], [1, 0.5, 0], [2, 0.5 + 1e-9, 0], [0, 0.5, 0]],
           "faces": [[0, 1, 2], [0, 3, 1], [0, 0, 1]]}  # a sliver, two vertices equal, one index twice
    with pytest.warns(OclgiWarning, match=r"dropped 3 degenerate triangles"):
        scene = load_dict({"mesh": [FLOOR, LIGHT, GROUND, bad]})
    assert scene.n_triangles == 6


def test_degeneracy_is_relative_to_each_triangle():
    # the same shape at any size is kept or dropped alike
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    sliver = np.array([[0, 0, 0], [1, 0, 0], [2, 1e-8, 0]], float)
    faces = np.array([[0, 1, 2]])
    for s in (1e-15, 1e-3, 1.0, 1e6, 1e15):
        assert not degenerate_triangles(tri * s, faces).any(), s
        assert degenerate_triangles(sliver * s, faces).all(), s


def test_degeneracy_as_float32_sees_it():
    # distinct in float64, one point in float32: the device sees no triangle
    v = np.array([[1.0, 1.0, 1.0], [1.0 + 1e-9, 1.0, 1.0], [1.0, 1.0 + 1e-9, 1.0]])
    assert degenerate_triangles(v, np.array([[0, 1, 2]])).all()
    # so tiny that the float32 normal flushes to zero
    assert degenerate_triangles(v * 1e-25 - 1e-25, np.array([[0, 1, 2]])).all()


# -- glTF with external buffers ------------------------------------------------------------

def _gltf_files():
    """A .gltf and the .bin buffers trimesh writes beside it (name -> bytes)."""
    quad = trimesh.Trimesh(vertices=LIGHT["vertices"], faces=LIGHT["faces"], process=False)
    files = trimesh.Scene(quad).export(file_type="gltf")
    assert any(name.endswith(".bin") for name in files) and "model.gltf" in files
    return files


def _zip(path, files, compression=zipfile.ZIP_STORED):
    """A zip file of ``files`` (member name -> data)."""
    with zipfile.ZipFile(path, "w", compression) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


def _write(folder, files):
    for name, data in files.items():
        (folder / name).write_bytes(data)


def test_gltf_with_external_buffers(tmp_path):
    _write(tmp_path, _gltf_files())
    mesh = load_mesh(tmp_path / "model.gltf")
    assert mesh.faces.shape == (2, 3)
    assert np.allclose(np.sort(mesh.vertices, axis=0), np.sort(np.array(LIGHT["vertices"], float), axis=0))


def test_gltf_with_external_buffers_in_a_zip(tmp_path):
    files = {f"scene/{name}": data for name, data in _gltf_files().items()}
    assert load_mesh(_zip(tmp_path / "m.zip", files)).faces.shape == (2, 3)


@pytest.mark.parametrize("in_zip", [False, True])
def test_gltf_missing_buffer_is_named(tmp_path, in_zip):
    files = {k: v for k, v in _gltf_files().items() if k != "gltf_buffer_0.bin"}
    if in_zip:
        path = _zip(tmp_path / "m.zip", files)
    else:
        _write(tmp_path, files)
        path = tmp_path / "model.gltf"
    with pytest.raises(OclgiError, match=r"model\.gltf: cannot read GLTF file: the file it names "
                                         r"'gltf_buffer_0\.bin' is missing beside it$"):
        load_mesh(path)


# -- PLY and OFF whose counts disagree with their data ---------------------------------------

PLY = ("ply\nformat {fmt} 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
       "element face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
ASCII_BODY = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
VERTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()


def _face(*idx):
    return np.array([len(idx)], "u1").tobytes() + np.array(idx, "<i4").tobytes()


def _ascii_ply(nv=3, nf=1, body=ASCII_BODY):
    return (PLY.format(fmt="ascii", nv=nv, nf=nf) + body).encode()


def _binary_ply(nv=3, nf=1, body=VERTS + _face(0, 1, 2)):
    return PLY.format(fmt="binary_little_endian", nv=nv, nf=nf).encode() + body


def _load(tmp_path, name, data):
    (tmp_path / name).write_bytes(data)
    return load_mesh(tmp_path / name)


@pytest.mark.parametrize("data, match", [
    # each of these loaded (4 vertices, no face; or a face short) without a word
    (_ascii_ply(nv=4), r"declares element counts vertex 4, face 1 \(5 lines of data\), the file holds 4 lines"),
    (_ascii_ply(nf=2), r"declares element counts vertex 3, face 2"),
    (_ascii_ply(body=ASCII_BODY + "3 0 2 1\n"), r"the file holds 5 lines"),
    (_ascii_ply(body=ASCII_BODY.replace("1 0 0", "1 0")), r"vertex 1 \(data line 2\) does not hold the numbers"),
    (_ascii_ply(nf=10_000_000_000), r"declares element counts vertex 3, face 10,000,000,000, more than its "
                                    r"26 bytes of data can hold"),
    (_binary_ply(nv=4), r"face 0 lists 0 vertices; a face needs at least 3"),
    (_binary_ply(nf=10_000_000_000), r"face 10,000,000,000, more than its 49 bytes"),
    (_binary_ply(body=VERTS + _face(0, 1, 2) + b"\0\0"), r"which take 49 bytes; the file holds 51 bytes"),
    (_ascii_ply().replace(b"property float z", b"property fuble z"),
     r"header line 6: unknown property type in 'property fuble z'"),
])
def test_ply_counts_must_match_the_data(tmp_path, data, match):
    with pytest.raises(OclgiError, match=r"m\.ply: cannot read PLY file: .*" + match):
        _load(tmp_path, "m.ply", data)


@pytest.mark.parametrize("data", [_ascii_ply(), _binary_ply(),
                                  _binary_ply(nf=2, body=VERTS + _face(0, 1, 2) + _face(2, 1, 0))])
def test_ply_that_is_right_loads(tmp_path, data):
    assert _load(tmp_path, "m.ply", data).faces.tolist()[0] == [0, 1, 2]


@pytest.mark.parametrize("data", [_ascii_ply(body=ASCII_BODY.replace("3 0 1 2", "3 0 1 -1")),
                                  _binary_ply(body=VERTS + _face(0, 1, -1))])
def test_ply_negative_face_index_refused(tmp_path, data):
    with pytest.raises(OclgiError, match=r"m\.ply: face indices out of range .*found -1"):
        _load(tmp_path, "m.ply", data)


OFF = "OFF\n{nv} {nf} 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"


@pytest.mark.parametrize("text, match", [
    (OFF.format(nv=4, nf=1), r"declares 4 vertices and 1 faces, 5 lines of data; the file holds 4 lines"),
    (OFF.format(nv=2, nf=1), r"declares 2 vertices and 1 faces"),
    (OFF.format(nv=3, nf=2), r"declares 3 vertices and 2 faces"),
    (OFF.format(nv=3, nf=10_000_000_000), r"10,000,000,000 faces"),
    (OFF.format(nv=3, nf=1) + "3 2 1 0\n", r"the file holds 5 lines"),
    (OFF.format(nv=3, nf=1).replace("3 0 1 2", "3 0 1"), r"face 0 does not give its count"),
    (OFF.format(nv=3, nf=1).replace("3 0 1 2", "3 0 1 -1"), r"face index outside the range"),
])
def test_off_counts_must_match_the_data(tmp_path, text, match):
    with pytest.raises(OclgiError, match=r"m\.off: cannot read OFF file: .*" + match):
        _load(tmp_path, "m.off", text.encode())


def test_off_with_comments_colours_and_counts_on_the_first_line_loads(tmp_path):
    text = "# made by hand\nOFF 3 1\n0 0 0 # origin\n1 0 0\n\n0 1 0\n3 0 1 2 255 0 0\n"
    assert _load(tmp_path, "m.off", text.encode()).faces.tolist() == [[0, 1, 2]]


# -- trimesh's failures in plain words -------------------------------------------------------

@pytest.mark.parametrize("name, data", [
    ("m.ply", _ascii_ply().replace(b"float z", b"fuble z")),  # was (KeyError: 'fuble')
    ("m.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty\nend_header\n0\n"),  # was an IndexError
    ("m.glb", trimesh.Scene(trimesh.creation.box()).export(file_type="glb")[:200]),
    ("m.glb", b"glTF" + bytes(40)),
    ("m.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\nendloop\nendfacet\nendsolid\n"),
    ("m.off", b"OFF\n3 1 0\n0 0 0\n1 0 x\n0 1 0\n3 0 1 2\n"),
])
def test_trimesh_failures_in_plain_words(tmp_path, capfd, name, data):
    with pytest.raises(OclgiError) as info:
        _load(tmp_path, name, data)
    msg = str(info.value)
    assert msg.startswith(str(tmp_path / name) + ": cannot read "), msg
    assert "\n" not in msg and "Error" not in msg and "()" not in msg and "array of size" not in msg, msg
    out, err = capfd.readouterr()
    assert "Traceback" not in err and out == "", err  # trimesh's logged tracebacks stay quiet


def test_missing_optional_package_is_named(tmp_path, monkeypatch):
    # an ASCII STL that is not UTF-8 (a Latin-1 name) needs charset-normalizer in trimesh
    monkeypatch.setitem(__import__("sys").modules, "charset_normalizer", None)
    stl = trimesh.creation.box().export(file_type="stl_ascii").encode()
    assert stl.startswith(b"solid")
    with pytest.raises(OclgiError, match=r"m\.stl: cannot read STL file: reading it needs the Python package "
                                         r"'charset-normalizer', which is not installed"):
        _load(tmp_path, "m.stl", b"solid caf\xe9" + stl[5:])


def test_optional_packages_the_formats_need_are_installed_with_oclgi():
    cfg = configparser.ConfigParser()
    cfg.read(Path(__file__).resolve().parent.parent / "setup.cfg")
    requires = [r.split(">")[0].split("=")[0].strip() for r in cfg["options"]["install_requires"].split("\n")]
    assert PACKAGES["charset_normalizer"] in requires


# -- zip members bounded before they inflate -------------------------------------------------

@pytest.fixture
def small_bound(monkeypatch):
    monkeypatch.setattr(zip_reader, "MAX_INFLATED", 4000)
    return 4000


def test_zip_member_over_the_bound_is_refused_by_its_header(tmp_path, small_bound):
    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "f 1 2 3\n" * 1000  # 8 kB
    _zip(tmp_path / "m.zip", {"big.obj": obj}, zipfile.ZIP_DEFLATED)
    with pytest.raises(OclgiError, match=r"m\.zip: member 'big\.obj' inflates to 8024 bytes, more than the "
                                         r"4000 bytes oclgi reads from one zip"):
        load_mesh(tmp_path / "m.zip")


def test_zip_bound_covers_all_members_together(tmp_path, small_bound):
    obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n" + "# padding\n" * 300
    mtl = "newmtl a\nKd 0.5 0.5 0.5\n" + "# padding\n" * 200
    _zip(tmp_path / "m.zip", {"m.obj": obj, "m.mtl": mtl}, zipfile.ZIP_DEFLATED)
    with pytest.raises(OclgiError, match=r"member 'm\.mtl' inflates to 2024 bytes, more than the 946 bytes left of the 4000 bytes "
                                         r"oclgi reads from one zip"):
        load_mesh(tmp_path / "m.zip")


def test_zip_header_that_lies_cannot_inflate_more(tmp_path, small_bound):
    big = "v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "f 1 2 3\n" * 100_000  # 800 kB, deflates to a few kB
    _zip(tmp_path / "m.zip", {"m.obj": big}, zipfile.ZIP_DEFLATED)
    raw = bytearray((tmp_path / "m.zip").read_bytes())
    # declare 100 bytes inflated, in the local header (offset 22) and the central directory (offset 24)
    raw[22:26] = struct.pack("<I", 100)
    cd = raw.rfind(b"PK\x01\x02")
    raw[cd + 24:cd + 28] = struct.pack("<I", 100)
    (tmp_path / "m.zip").write_bytes(bytes(raw))
    with pytest.raises(OclgiError, match=r"m\.zip: .*'m\.obj'"):
        load_mesh(tmp_path / "m.zip")


# -- scene values: float32's range, nesting, seeds --------------------------------------------

def _scene(tmp_path, toml):
    (tmp_path / "s.toml").write_text(toml)
    return load_file(tmp_path / "s.toml")


QUADS = ("[[mesh]]\nvertices = [[-1, 0, -1], [1, 0, -1], [1, 0, 1]]\nfaces = [[0, 2, 1]]\n"
         "[[mesh]]\nvertices = [[0, 1, 0], [0.2, 1, 0], [0, 1, 0.2]]\nfaces = [[0, 1, 2]]\nemission = [1, 1, 1]\n")


LIT = "[[point_light]]\nposition = [0, 1, 0]\nintensity = "


@pytest.mark.parametrize("extra, match", [
    # each of these was accepted (inf on the device) or a traceback (an integer past float's range)
    ("[camera]\nposition = [1e39, 0, 0]\nlook_at = [0, 0, 0]\n",
     r"camera\.position: expected 3 numbers, each from -1e18 to 1e18"),
    ("[camera]\nposition = [0, 0, 3]\nlook_at = [0, -1e30, 0]\n", r"camera\.look_at: expected 3 numbers, each from"),
    ("[[point_light]]\nposition = [0, 1e39, 0]\nintensity = [1, 1, 1]\n",
     r"point_light\[0\]\.position: expected 3 numbers, each from -1e18 to 1e18"),
    ("[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 1" + "0" * 400 + "\n",
     r"camera\.fov: expected a number from -3\.4e38 to 3\.4e38 \(float32 on the device\)"),
    (LIT + "[1" + "0" * 400 + ", 0, 0]\n", r"point_light\[0\]\.intensity: expected 3 numbers"),
    (LIT + "[1e39, 0, 0]\n",
     r"point_light\[0\]\.intensity: expected 3 numbers, each 0 or from 1\.2e-38 to 3\.4e38 \(float32"),
    (LIT + "[1e-46, 0, 0]\n", r"point_light\[0\]\.intensity: expected 3 numbers, each 0 or from 1\.2e-38"),
])
def test_scene_values_beyond_float32_refused(tmp_path, extra, match):
    with pytest.raises(OclgiError, match=r"^" + match):
        _scene(tmp_path, QUADS + extra)


@pytest.mark.parametrize("nested", ["a = " + "[" * 1000 + "]" * 1000,
                                    "a = " + "{b = " * 1000 + "1" + "}" * 1000])
def test_deeply_nested_toml_is_one_error(tmp_path, nested):
    with pytest.raises(OclgiError, match=r"s\.toml: malformed TOML: arrays or tables nested too deeply$"):
        _scene(tmp_path, nested + "\n")


def test_seed_past_2_64_refused(tmp_path):
    with pytest.raises(OclgiError, match=r"photons\.seed: expected an integer in 0\.\.2\^64-1"):
        _scene(tmp_path, QUADS + f"[photons]\nseed = {2**64}\n")


def test_gltf_buffer_over_the_zip_bound_is_named(tmp_path, monkeypatch):
    files = _gltf_files()
    monkeypatch.setattr(zip_reader, "MAX_INFLATED", len(files["model.gltf"]) + 10)
    with pytest.raises(OclgiError, match=r"m\.zip: member 'gltf_buffer_\d\.bin' inflates to \d+ bytes, more than "
                                         r"the 10 bytes left"):
        load_mesh(_zip(tmp_path / "m.zip", files))


def test_real_meshes_still_load(scenes_dir):
    bunny = load_mesh(scenes_dir / "stanford-bunny" / "bun_zipper.ply")  # ASCII PLY with extra properties
    assert bunny.vertices.shape == (35947, 3) and bunny.faces.shape == (69451, 3)
    sponza = load_mesh(scenes_dir / "sponza-dabrovic" / "sponza.zip")  # an OBJ in a zip
    assert sponza.faces.shape == (66454, 3)


def test_room_with_huge_ground_plane_runs(tmp_path):
    # was "the scene has no emitter": the light's triangles were dropped as degenerate
    from cli_run import run

    def mesh(m):
        return f"[[mesh]]\nvertices = {m['vertices']}\nfaces = {m['faces']}\nemission = {m.get('emission', [0, 0, 0])}\n"

    (tmp_path / "s.toml").write_text(mesh(FLOOR) + mesh(LIGHT) + mesh(GROUND) +
                                     "[photons]\ncount = 2000\n[estimator]\nradius = 0.1\n")
    (tmp_path / "p.csv").write_text("x,y,z,nx,ny,nz\n0,0.01,0,0,1,0\n")
    res = run(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", "e.csv", "--quiet")
    assert res.returncode == 0 and "degenerate" not in res.stderr, res.stderr
    e = np.loadtxt(tmp_path / "e.csv", delimiter=",", skiprows=1)
    assert e.shape == (9,) and np.isfinite(e).all()


@pytest.mark.parametrize("name, export", [
    ("m.glb", lambda box: trimesh.Scene(box).export(file_type="glb")),
    ("m.gltf", lambda box: trimesh.Scene(box).export(file_type="gltf", embed_buffers=True)["model.gltf"]),
    ("m.stl", lambda box: box.export(file_type="stl")),
    ("m.stl", lambda box: box.export(file_type="stl_ascii").encode()),
    ("m.off", lambda box: box.export(file_type="off").encode()),
    ("m.ply", lambda box: box.export(file_type="ply", encoding="ascii")),
    ("m.ply", lambda box: box.export(file_type="ply")),
])
def test_each_format_loads_a_box(tmp_path, name, export):
    mesh = _load(tmp_path, name, export(trimesh.creation.box()))
    assert mesh.faces.shape == (12, 3) and np.allclose(np.abs(mesh.vertices), 0.5)


def test_dict_keys_that_are_not_names_are_refused():
    """A dict made in Python may have keys TOML cannot: one line, not a
    TypeError from sorting them with the names."""
    for desc, message in (({"mesh": {0: 1, "x": 2}}, "got 0"), ({1: 2}, "got 1")):
        with pytest.raises(OclgiError, match=f"keys must be names \\(strings\\), {message}"):
            oclgi.load_dict(desc)
