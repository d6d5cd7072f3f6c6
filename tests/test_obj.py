"""oclgi's own OBJ/MTL reader, checked on McGuire's Cornell box.

``CornellBox-Original.obj`` uses relative (negative) face indices and TABs
after ``v``; ``CornellBox-Original.trimesh-safe.obj`` is the same geometry
with absolute indices and plain spaces. trimesh reads the safe file right and
the original wrong, which is why oclgi reads OBJ itself.
"""

import warnings
import zipfile

import numpy as np
import pytest
import trimesh

from oclgi.errors import OclgiError
from oclgi.scene.description import load_file
from oclgi.scene.mesh import load_mesh
from oclgi.scene.obj import read_obj
from oclgi.scene.scene import OclgiWarning

BOX_LO = [-1.02, 0.0, -1.04]
BOX_HI = [1.0, 1.99, 0.99]


def _triangles(vertices, faces):
    """Triangles as sorted, rounded vertex coordinates (winding kept up to rotation)."""
    out = []
    for tri in np.round(np.asarray(vertices, np.float64)[np.asarray(faces)], 6):
        rows = [tuple(r) for r in tri.tolist()]
        k = min(range(3), key=lambda i: rows[i])
        out.append(tuple(rows[k:] + rows[:k]))
    return sorted(out)


@pytest.fixture(scope="module")
def box_dir(scenes_dir):
    return scenes_dir / "cornell-box"


@pytest.fixture(scope="module")
def original(box_dir):
    return read_obj(box_dir / "CornellBox-Original.obj")


@pytest.fixture(scope="module")
def trimesh_safe(box_dir):
    return trimesh.load(box_dir / "CornellBox-Original.trimesh-safe.obj", force="mesh", process=False)


def test_original_file_is_the_tricky_one(box_dir):
    text = (box_dir / "CornellBox-Original.obj").read_text()
    assert any(line.startswith("f -") for line in text.splitlines()), "expected relative indices"
    safe = (box_dir / "CornellBox-Original.trimesh-safe.obj").read_text()
    assert not any(line.startswith("f -") for line in safe.splitlines())


def test_reader_matches_trimesh_on_safe_file(original, trimesh_safe):
    assert original.faces.shape == (36, 3) and len(trimesh_safe.faces) == 36
    assert _triangles(original.vertices, original.faces) == _triangles(trimesh_safe.vertices, trimesh_safe.faces)


def test_reader_bounds(original):
    used = original.vertices[np.unique(original.faces)]
    np.testing.assert_allclose(used.min(axis=0), BOX_LO)
    np.testing.assert_allclose(used.max(axis=0), BOX_HI)


def test_trimesh_gets_the_original_wrong(box_dir, original):
    """Documents why oclgi has its own reader: trimesh mis-reads the original.

    If this starts failing, trimesh has learnt relative indices and TABs; the
    own reader is then a candidate for removal, not this test for deletion.
    """
    m = trimesh.load(box_dir / "CornellBox-Original.obj", force="mesh", process=False)
    wrong_bounds = not (np.allclose(m.bounds[0], BOX_LO) and np.allclose(m.bounds[1], BOX_HI))
    wrong_tris = len(m.faces) != 36 or _triangles(m.vertices, m.faces) != _triangles(original.vertices, original.faces)
    assert wrong_bounds or wrong_tris


def test_materials_come_through(original):
    assert original.material_names == [
        "floor", "ceiling", "backWall", "rightWall", "leftWall", "shortBox", "tallBox", "light"]
    assert original.materials["light"].emission == pytest.approx((17.0, 12.0, 4.0))
    # every material named by usemtl is defined in the .mtl, and only the light emits
    for name in original.material_names:
        mat = original.materials[name]
        assert mat.albedo is not None and all(0 <= a <= 1 for a in mat.albedo), name
        if name != "light":
            assert mat.emission is None or max(mat.emission) == 0, name
    # the light is two triangles facing down
    light_faces = original.faces[original.face_material == original.material_names.index("light")]
    assert len(light_faces) == 2
    v = original.vertices[light_faces]
    assert (np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])[:, 1] < 0).all()
    np.testing.assert_allclose(v[..., 1], 1.98)


def test_scene_material_of_light(scenes_dir):
    """Through the scene description the light keeps its Ke and is the emitter."""
    scene = load_file(scenes_dir / "cornell_box.toml")
    emissive = [m for m in scene.materials if max(m.emission) > 0]
    assert [m.emission for m in emissive] == [pytest.approx((17.0, 12.0, 4.0))]
    assert emissive[0].name.endswith(":light") and scene.n_triangles == 36


# -- the reader on small hand-written files --------------------------------------

def _write(tmp_path, text, name="m.obj"):
    (tmp_path / name).write_text(text)
    return tmp_path / name


def test_relative_indices_tabs_and_polygons(tmp_path):
    p = _write(tmp_path, "v\t0 0 0\nv 1\t0 0\nv  1 1 0\nv 0 1 0\nf -4 -3 -2 -1\nv 5 5 5\nf 1/1/1 2//2 -1\n")
    m = read_obj(p)
    assert m.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 4]] and m.face_material.tolist() == [-1, -1, -1]


@pytest.mark.parametrize("text, match", [
    ("v 1 2 x\nv 0 0 0\nv 1 0 0\nf 1 2 3\n", r"m\.obj:1: malformed number"),
    ("v 1 2\nf 1 1 1\n", r"m\.obj:1: expected 3 numbers"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"m\.obj:4: face index '4' refers to no vertex"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", r"m\.obj:4: face index '0'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", r"m\.obj:4: face index '-4'"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", r"m\.obj:4: malformed face index"),
    ("v 0 0 0\nv 1 0 0\nf 1 2\n", r"m\.obj:3: a face needs at least 3 vertices"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", r"m\.obj: no faces"),
    ("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", r"m\.obj:1: vertex coordinate is NaN or infinite"),
    ("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", r"m\.obj:2: vertex coordinate is NaN or infinite"),
    ("v 0 0 0\nv 1 0 0\nv 0 -1e999 0\nf 1 2 3\n", r"m\.obj:3: vertex coordinate is NaN or infinite"),
])
def test_malformed_obj_names_the_line(tmp_path, text, match):
    with pytest.raises(OclgiError, match=match):
        read_obj(_write(tmp_path, text))


def test_missing_mtllib_warns(tmp_path):
    p = _write(tmp_path, "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n")
    with pytest.warns(OclgiWarning, match=r"material library 'nowhere\.mtl' not found"):
        m = read_obj(p)
    assert m.material_names == ["a"] and m.materials == {}


def test_mtllib_found_is_silent(tmp_path):
    (tmp_path / "my mats.mtl").write_text("newmtl a\nKd 0.1 0.2 0.3\nKe 1 2 3\n")
    p = _write(tmp_path, "mtllib my mats.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = read_obj(p)
    assert m.materials["a"].albedo == pytest.approx((0.1, 0.2, 0.3))
    assert m.materials["a"].emission == pytest.approx((1, 2, 3))


def test_malformed_mtl_is_an_error(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl a\nKd 0.1 zz 0.3\n")
    p = _write(tmp_path, "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n")
    with pytest.raises(OclgiError, match=r"m\.mtl:2: malformed number"):
        read_obj(p)


def test_obj_in_zip_reads_its_mtllib(tmp_path):
    z = tmp_path / "mesh.zip"
    with zipfile.ZipFile(z, "w") as f:
        f.writestr("m.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl glow\nf 1 2 3\n")
        f.writestr("m.mtl", "newmtl glow\nKe 4 5 6\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh = load_mesh(z)
    assert mesh.names == ["", "glow"] and mesh.materials["glow"].emission == pytest.approx((4, 5, 6))
