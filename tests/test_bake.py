"""``oclgi bake``: the solution at the vertices of the tessellated scene in a
glTF 2.0 file; the file is valid (read by pygltflib, a reader other than the
writer's) and round-trips (the values read back equal the API's)."""

import json
import struct

import numpy as np
import pygltflib
import pytest
import trimesh

import oclgi
from cli_run import in_process
from oclgi.bake import bake, write_glb
from oclgi.incremental.attached_points import AttachedPoints
from oclgi.scene.tessellate import tessellate

EDGE = 0.15
PHOTONS = 30_000


@pytest.fixture(scope="module")
def moved(scenes_dir):
    engine = oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_bunny.toml"))
    m = np.eye(4)
    m[:3, 3] = [0.25, 0.0, -0.1]
    engine.move("bunny", m)
    return engine, m


def _glb_json(path):
    data = path.read_bytes()
    assert data[:4] == b"glTF" and struct.unpack("<I", data[4:8])[0] == 2
    n = struct.unpack("<I", data[12:16])[0]
    return json.loads(data[20:20 + n])


def test_bake_round_trips_and_equals_the_api(moved, tmp_path):
    engine, m = moved
    result = bake(engine, edge=EDGE, photons=PHOTONS)
    # the API's values are the estimate at the tessellated vertices, the bunny's where the engine has it
    tess = tessellate(engine.scene, EDGE)
    placed = AttachedPoints(engine, tess.points(), as_loaded=True)
    placed.update()
    expected = engine.irradiance(placed.points, photons=PHOTONS).irradiance
    path = tmp_path / "room.glb"
    write_glb(result, path)
    back = trimesh.load(path, process=False)
    assert set(back.geometry) == {"static", "bunny"}
    total = 0
    for name, mesh in result.geometry.items():
        got = back.geometry[name]
        np.testing.assert_array_equal(got.vertex_attributes["_IRRADIANCE"], mesh.vertex_attributes["_IRRADIANCE"])
        np.testing.assert_array_equal(np.asarray(got.visual.vertex_colors), np.asarray(mesh.visual.vertex_colors))
        np.testing.assert_array_equal(got.faces, mesh.faces)
        np.testing.assert_allclose(got.vertices, mesh.vertices, rtol=0, atol=1e-6)
        total += len(mesh.vertices)
    assert total == len(tess.vertices)
    # every vertex's value is the API's at that vertex: match them by position
    values = np.concatenate([mesh.vertex_attributes["_IRRADIANCE"] for mesh in result.geometry.values()])
    pos = np.concatenate([mesh.vertices for mesh in result.geometry.values()]).astype(np.float32)
    order = np.lexsort(placed.points.positions[:, :3].T)
    mine = np.lexsort(pos.T)
    np.testing.assert_array_equal(pos[mine], placed.points.positions[order, :3])
    np.testing.assert_array_equal(values[mine], expected[order].astype(np.float32))
    # the bunny is baked where it was moved to
    bunny = result.geometry["bunny"].vertices
    a, b = engine.scene.object_ranges()[1]
    original = engine.scene.vertices[np.unique(engine.scene.faces[a:b])]
    np.testing.assert_allclose(bunny.mean(axis=0), original.mean(axis=0) + m[:3, 3], atol=2e-3)
    # lit and dark where they should be: the floor is lit, nothing is negative
    assert (values >= 0).all() and np.median(values[:, 0]) > 0.1


def test_the_file_is_valid_gltf(moved, tmp_path):
    engine, _ = moved
    path = tmp_path / "room.glb"
    write_glb(bake(engine, edge=EDGE, photons=PHOTONS, quantity="radiance", exposure=2.0), path)
    g = pygltflib.GLTF2().load(str(path))
    assert g.asset.version == "2.0"
    blob = g.binary_blob()
    sizes = {pygltflib.FLOAT: 4, pygltflib.UNSIGNED_BYTE: 1, pygltflib.UNSIGNED_INT: 4, pygltflib.UNSIGNED_SHORT: 2}
    widths = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}
    for acc in g.accessors:  # every accessor fits its buffer view, which fits the buffer
        view = g.bufferViews[acc.bufferView]
        assert (acc.byteOffset or 0) + acc.count * sizes[acc.componentType] * widths[acc.type] <= view.byteLength
        assert (view.byteOffset or 0) + view.byteLength <= len(blob)
    names = {g.nodes[i].name for i in g.scenes[g.scene].nodes} | {n.name for n in g.nodes}
    assert {"static", "bunny"} <= names
    for mesh in g.meshes:
        for prim in mesh.primitives:
            attrs = {k: v for k, v in prim.attributes.__dict__.items() if v is not None}
            attrs.update(getattr(prim.attributes, "_extra", {}) or {})
            pos = g.accessors[prim.attributes.POSITION]
            assert pos.min is not None and pos.max is not None  # required for POSITION
            col = g.accessors[prim.attributes.COLOR_0]
            assert col.componentType == pygltflib.UNSIGNED_BYTE and col.normalized and col.type == "VEC4"
            assert prim.attributes.NORMAL is not None
    raw = _glb_json(path)
    custom = {k for m in raw["meshes"] for p in m["primitives"] for k in p["attributes"] if k.startswith("_")}
    assert custom == {"_RADIANCE", "_COLOR_SRGB"}


def test_radiance_is_emission_plus_reflected(moved):
    engine, _ = moved
    r = bake(engine, edge=0.3, photons=PHOTONS, quantity="radiance")
    e = bake(engine, edge=0.3, photons=PHOTONS)
    static_r = r.geometry["static"].vertex_attributes["_RADIANCE"]
    static_e = e.geometry["static"].vertex_attributes["_IRRADIANCE"]
    light = static_r.max(axis=1) >= 12.0  # the Cornell light emits (17, 12, 4)
    assert light.any() and (~light).any()
    # off the light, L = albedo E / pi <= E / pi
    assert (static_r[~light] <= static_e[~light] / np.pi * (1 + 1e-6) + 1e-9).all()


def test_bake_command(monkeypatch, capsys, scenes_dir, tmp_path):
    scene = scenes_dir / "cornell_box.toml"
    out = tmp_path / "box.glb"
    r = in_process(monkeypatch, capsys, tmp_path, "bake", scene, "-o", out, "--photons", 20_000, "--edge", 0.3,
                   "--quiet")
    assert r.returncode == 0, r.stderr
    assert f"wrote {out}" in r.stdout and out.stat().st_size > 1000
    assert len(trimesh.load(out, process=False).geometry) == 1
    for args, words in (((["-o", tmp_path / "x.gltf"]), "must end in .glb"),
                        ((["-o", tmp_path / "y.glb", "--edge", "0"]), "edge"),
                        ((["-o", tmp_path / "z.glb", "--edge", "1e-5"]), "vertices \\(at most"),
                        ((["-o", tmp_path / "t.glb", "--edge", "1e-30"]), "vertices \\(at most"),  # no overflow
                        ((["-o", tmp_path / "w.glb", "--quantity", "power"]), "quantity")):
        r = in_process(monkeypatch, capsys, tmp_path, "bake", scene, "--photons", 1000, *args)
        assert r.returncode == 2, (args, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith(("oclgi: error:", "usage:")) or \
            "error" in r.stderr, r.stderr
        import re
        assert re.search(words, r.stderr), (words, r.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["box.glb"]  # nothing partial left
