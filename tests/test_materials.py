"""Materials in scenes: reading them from files and scene tables, camera
paths through mirrors and glass, and the incremental session's exactness
with a glass object moving."""

from __future__ import annotations

import json
import struct
import warnings

import numpy as np
import pytest
import trimesh
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

import oclgi
from oclgi.errors import OclgiError
from test_instances import _rigid


def test_mtl_illumination_models_become_kinds(scenes_dir):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = oclgi.load_dict({"mesh": [{"path": str(scenes_dir / "cornell-box" / "CornellBox-Sphere.obj")}]})
    kinds = {m.name.split(":")[-1]: m for m in scene.materials}
    assert kinds["leftSphere"].kind == "mirror" and kinds["leftSphere"].specular == (0.95, 0.95, 0.95)
    glass = kinds["rightSphere"]
    # MTL glass as Blender's and three.js's importers read it: clear, at its Ni (Ks 0.3 and Tf 0.1 no tints)
    assert glass.kind == "dielectric" and glass.ior == 2.5
    assert glass.transmission == (1.0, 1.0, 1.0) and glass.specular == (1.0, 1.0, 1.0)
    assert kinds["floor"].kind == "diffuse"
    text = [str(w.message) for w in caught]
    # the mirror's and the glass's Kd 0.01 cannot be honoured: one warning each, naming the material
    assert sum("leftSphere" in t and "Kd" in t for t in text) == 1
    assert sum("rightSphere" in t and "Kd" in t for t in text) == 1
    # the glass's tints are named as read otherwise, in the same one warning
    assert sum("rightSphere" in t and "Tf 0.1 0.1 0.1" in t and "Ks 0.3 0.3 0.3" in t for t in text) == 1
    assert not any("almost black" in t for t in text)


def test_dark_glass_is_said(scenes_dir):
    """A glass material that transmits under a tenth of the light (a scene
    file's tint) is said when the scene is made; clear glass is not."""
    obj = str(scenes_dir / "cornell-box" / "CornellBox-Sphere.obj")
    for tint, said in ((0.05, True), (0.5, False)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            oclgi.load_dict({"mesh": [{"path": obj, "materials": {"rightSphere": {
                "kind": "dielectric", "transmission": [tint, tint, tint]}}}]})
        dark = [str(w.message) for w in caught if "almost black" in str(w.message)]
        assert len(dark) == int(said), dark
        assert not said or "rightSphere" in dark[0]


def test_mtl_phong_is_scaled_to_conserve_energy(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl shiny\nKd 0.6 0.6 0.6\nKs 0.6 0.6 0.6\nNs 20\nillum 2\n"
                                    "newmtl tex\nKd 0.5 0.5 0.5\nmap_Kd wood.png\nd 0.5\n")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                                    "usemtl shiny\nf 1 2 3\nusemtl tex\nf 2 4 3\n")
    with pytest.warns(oclgi.OclgiWarning) as caught:
        scene = oclgi.load_dict({"mesh": [{"path": str(tmp_path / "m.obj"), "emission": [1, 1, 1]}]})
    shiny = next(m for m in scene.materials if m.name.endswith("shiny"))
    assert shiny.kind == "phong" and shiny.exponent == 20
    bound = max(shiny.albedo) + max(shiny.specular) * 22 / 21
    assert 0.999 < bound <= 1.0 and shiny.albedo[0] / shiny.specular[0] == pytest.approx(1.0)
    text = " ".join(str(w.message) for w in caught)
    assert "scaled" in text and "map_Kd 'wood.png'" in text and "d 0.5" in text


def test_scene_tables_set_kinds_and_refuse_what_a_kind_does_not_read(scenes_dir):
    base = {"path": str(scenes_dir / "cornell-box" / "CornellBox-Original.obj")}
    scene = oclgi.load_dict({"mesh": [dict(base, materials={"shortBox": {"kind": "conductor", "roughness": 0.2,
                                                                          "specular": [0.9, 0.6, 0.3]}})]})
    box = next(m for m in scene.materials if m.name.endswith("shortBox"))
    assert (box.kind, box.roughness, box.specular) == ("conductor", 0.2, (0.9, 0.6, 0.3))
    bad = [({"kind": "velvet"}, "kind"), ({"kind": "mirror", "ior": 1.5}, "takes no ior"),
           ({"kind": "dielectric", "ior": 0.5}, "ior"), ({"kind": "conductor", "roughness": 0}, "roughness"),
           ({"kind": "phong", "albedo": [0.5] * 3, "specular": [0.6] * 3}, "at most 1"),
           ({"kind": "mirror", "emission": [1, 1, 1]}, "cannot emit"), ({"twosided": 1}, "true or false")]
    for table, words in bad:
        with pytest.raises(OclgiError, match=words):
            oclgi.load_dict({"mesh": [dict(base, materials={"shortBox": table})]})


def _room(scenes_dir, bunny_material, **extra):
    return oclgi.load_dict({
        "mesh": [
            {"path": str(scenes_dir / "cornell-box" / "CornellBox-Original.obj")},
            {"path": str(scenes_dir / "stanford-bunny" / "bun_zipper.ply"), "movable": True, "name": "bunny",
             "transform": {"scale": 4.0, "translate": [0.3, -0.13, 0.3]}, "material": bunny_material},
        ],
        "photons": {"count": 10_000, "seed": 5, "max_depth": 10},
        "camera": {"position": [0, 1, 3.94], "look_at": [0, 1, 0], "fov": 39.3, "width": 24, "height": 24},
        **extra,
    }, base_dir=scenes_dir)


def test_a_mirror_shows_the_points_it_reflects(cl_env):
    """A camera looking at a mirror sees, at each pixel, the point of the
    lit floor the reflected ray meets, weighted by the mirror's
    reflectance: the same point and weight the law of reflection gives."""
    mirror = {"vertices": [[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], "faces": [[0, 2, 1], [0, 3, 2]],
              "material": {"kind": "mirror", "specular": [0.8, 0.7, 0.6]}}
    wall = {"vertices": [[-4, -4, -3], [4, -4, -3], [4, 4, -3], [-4, 4, -3]], "faces": [[0, 1, 2], [0, 2, 3]],
            "albedo": [0.5, 0.5, 0.5]}
    scene = oclgi.load_dict({"mesh": [mirror, wall], "point_light": {"position": [0, 3, 0], "intensity": [5, 5, 5]},
                             "camera": {"position": [0, 1, 2], "look_at": [0, 0, -1], "width": 16, "height": 16}})
    pts = oclgi.Engine(scene).camera_points()
    on_wall = pts.tri >= 2
    reflected = on_wall & (pts.weights[:, 0] < 1)
    direct = on_wall & ~reflected
    assert reflected.sum() > 30 and direct.sum() > 30
    np.testing.assert_allclose(pts.weights[reflected, :3], np.tile([0.8, 0.7, 0.6], (reflected.sum(), 1)), rtol=1e-6)
    assert (pts.weights[direct, :3] == 1).all()
    # a reflected point lies on the line from the camera's mirror image (0, -1, 2) through
    # the mirror (y = 0); a directly seen one on a line from the eye that stays above it
    for eye, sel, crosses in (((0.0, -1.0, 2.0), reflected, True), ((0.0, 1.0, 2.0), direct, False)):
        p = pts.positions[sel, :3].astype(np.float64)
        t = -eye[1] / (p[:, 1] - eye[1])
        assert (((t > 0) & (t < 1)) == crosses).all()
    np.testing.assert_allclose(pts.positions[on_wall, 2], -3.0, atol=1e-5)


def test_camera_paths_are_the_same_for_diffuse_scenes(cornell):
    """All-diffuse scenes: every visible point has weight 1; a pixel that
    sees nothing holds its ray's direction, weight 1 and no coverage."""
    cam = cornell.view_camera(width=32, height=32)
    pts = cornell.camera_points(width=32, height=32)
    hit = pts.tri >= 0
    assert hit.sum() > 500 and (~hit).sum() > 50 and (pts.weights[hit] == 1).all()
    np.testing.assert_array_equal(pts.weights[~hit], np.tile([1, 1, 1, 0], ((~hit).sum(), 1)))
    d = pts.positions[~hit, :3].astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)
    assert (d @ (np.subtract(cam.look_at, cam.position) / np.linalg.norm(np.subtract(cam.look_at, cam.position)))
            > 0.8).all()


@pytest.mark.parametrize("kind", ["dielectric", "mirror", "rough_dielectric"])
def test_session_with_a_specular_object_moving_equals_recomputation(scenes_dir, rng, kind):
    """A glass (or mirror) bunny moves; the camera session's view, sums and
    image equal a fresh session's and plain DETP over a fresh camera pass,
    bit for bit."""
    table = {"kind": kind, **({"ior": 1.5} if "dielectric" in kind else {}),
             **({"roughness": 0.3} if kind == "rough_dielectric" else {})}
    engine = oclgi.Engine(_room(scenes_dir, table))
    session = oclgi.Session(engine, method="detp_disc_index", radius=0.05, photons=10_000)
    first, _ = session.render()
    recomputed = 0
    for _ in range(6):
        m = _rigid(rng, shift=0.5)
        m[:3, 3] = np.clip(m[:3, 3], -0.5, 0.5)
        recomputed += session.move("bunny", m).points
    assert recomputed > 0
    engine = session.engine  # the session's pose, for the recomputations
    fresh = oclgi.Session(engine, method="detp_disc_index", radius=0.05, photons=10_000)
    assert session.points.positions.tobytes() == fresh.points.positions.tobytes()
    assert session.points.weights.tobytes() == fresh.points.weights.tobytes()
    assert np.array_equal(session.accumulators(), fresh.accumulators())
    plain = engine.irradiance(engine.camera_points(), method="detp", radius=0.05, photons=10_000)
    assert np.array_equal(session.accumulators(), plain.accumulators)
    assert np.array_equal(session.render()[0], fresh.render()[0])
    session.move("bunny", np.eye(4))
    assert np.array_equal(session.render()[0], first)


def test_retrace_through_glass_equals_a_fresh_trace(scenes_dir, rng):
    """Photon paths through a moved glass object: the session's store equals
    a fresh trace at the new pose, bit for bit."""
    engine = oclgi.Engine(_room(scenes_dir, {"kind": "dielectric", "ior": 1.5}))
    session = oclgi.Session(engine, points=engine.camera_points(), method="detp", radius=0.05, photons=10_000)
    for _ in range(4):
        session.move("bunny", _rigid(rng, shift=0.4))
    seg, plen = session.segments()
    engine = session.engine  # at the session's pose
    fresh_seg, fresh_len = engine.trace(10_000, seed=5, max_depth=10)
    assert np.array_equal(plen, fresh_len)
    stored = seg.copy()
    stored["power"] *= engine.photon_watts(10_000)
    assert stored.tobytes() == fresh_seg.tobytes()


def test_the_sky_is_seen_where_rays_leave_the_scene():
    """A camera looking up from under a mirror-less open box sees the sky's
    radiance above the horizon, black below it; with a sky every pixel is
    covered (alpha 1)."""
    floor = {"vertices": [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], "faces": [[0, 2, 1], [0, 3, 2]]}
    scene = oclgi.load_dict({"mesh": [floor], "sky": {"radiance": [0.2, 0.3, 0.5]},
                             "camera": {"position": [0, 0.5, 3], "look_at": [0, 0.5, 0], "width": 16, "height": 16,
                                        "fov": 90}})
    r = oclgi.Engine(scene).render(photons=20_000, radius=0.1)
    assert (r.pixels[..., 3] == 255).all()
    np.testing.assert_allclose(r.radiance[0, 0], [0.2, 0.3, 0.5], rtol=1e-6)  # the top corner: sky
    assert r.radiance[-1, 0].max() == 0  # below the horizon, past the floor: black


def test_photon_maps_store_no_impacts_on_mirrors(cl_env):
    """Impacts are where density is estimated: on the diffuse wall, none on
    the mirror floor (its photons go on, and land on the wall)."""
    mirror = {"vertices": [[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], "faces": [[0, 2, 1], [0, 3, 2]],
              "material": {"kind": "mirror"}}
    wall = {"vertices": [[-4, 0, -3], [4, 0, -3], [4, 8, -3], [-4, 8, -3]], "faces": [[0, 1, 2], [0, 2, 3]]}
    scene = oclgi.load_dict({"mesh": [mirror, wall], "point_light": {"position": [0, 3, 0], "intensity": [5, 5, 5]}})
    engine = oclgi.Engine(scene)
    pts = oclgi.query_points(np.array([[0.0, 1.0, -3.0]]), np.array([[0.0, 0.0, 1.0]]))
    run = engine.run(pts, method="photon_map", photons=20_000, k=10)
    run.complete()
    impacts = np.concatenate([c[0] for c in run.estimator.chunks])
    assert len(impacts) > 1000
    np.testing.assert_allclose(impacts[:, 2], -3.0, atol=1e-4)  # all on the wall
    seg, _ = engine.trace(20_000)
    assert ((seg["tri"] >= 0) & (seg["tri"] < 2)).sum() > 1000  # photons did hit the mirror


def _quad(y, material):
    """A trimesh square at height y, facing up, of the given material."""
    q = trimesh.Trimesh([[-1, y, -1], [1, y, -1], [1, y, 1], [-1, y, 1]], [[0, 2, 1], [0, 3, 2]], process=False)
    q.visual = TextureVisuals(material=material)
    return q


def test_gltf_materials_are_named_by_material_and_read_as_kinds(tmp_path):
    """glTF metallic-roughness: a metal becomes a GGX conductor (alpha =
    roughness^2), a dielectric a diffuse surface; overrides are keyed by
    the material's name, which geometries sharing it share."""
    gold = PBRMaterial(name="gold", baseColorFactor=[255, 200, 80, 255], metallicFactor=1.0, roughnessFactor=0.5)
    paint = PBRMaterial(name="paint", baseColorFactor=[128, 128, 255, 255], metallicFactor=0.0, roughnessFactor=0.9)
    lamp = PBRMaterial(name="lamp", baseColorFactor=[0, 0, 0, 255], emissiveFactor=[1, 1, 1])
    trimesh.Scene({"a": _quad(0.0, gold), "b": _quad(0.5, gold), "c": _quad(1.0, paint),
                   "light": _quad(2.0, lamp)}).export(tmp_path / "s.glb")
    scene = oclgi.load_dict({"mesh": [{"path": str(tmp_path / "s.glb"),
                                       "materials": {"paint": {"albedo": [0.2, 0.3, 0.4]}}}]})
    by_name = {m.name.split(":")[-1]: m for m in scene.materials}
    assert set(by_name) >= {"gold", "paint", "lamp"}
    g = by_name["gold"]
    assert g.kind == "conductor" and g.roughness == pytest.approx(0.25)
    assert g.specular == pytest.approx((1.0, 200 / 255, 80 / 255))
    assert by_name["paint"].kind == "diffuse" and by_name["paint"].albedo == (0.2, 0.3, 0.4)
    assert np.bincount(scene.tri_material)[[m.name.endswith("gold") for m in scene.materials].index(True)] == 4


def test_a_gltf_camera_is_used_when_the_scene_names_none(tmp_path):
    s = trimesh.Scene(trimesh.creation.box())
    s.set_camera(angles=(0, 0, 0), distance=5, fov=(60, 45))
    s.export(tmp_path / "s.glb")
    scene = oclgi.load_dict({"mesh": [{"path": str(tmp_path / "s.glb"), "emission": [1, 1, 1],
                                       "transform": {"translate": [0, 1, 0]}}]})
    cam = scene.camera
    assert cam is not None and cam.fov == pytest.approx(45.0)
    np.testing.assert_allclose(cam.position, [0, 1, 5], atol=1e-9)  # the node's place, moved with the mesh
    np.testing.assert_allclose(np.subtract(cam.look_at, cam.position), [0, 0, -1], atol=1e-9)
    assert cam.width == round(256 * 4 / 3) and cam.height == 256
    named = oclgi.load_dict({"mesh": [{"path": str(tmp_path / "s.glb"), "emission": [1, 1, 1]}],
                             "camera": {"position": [0, 0, 9], "look_at": [0, 0, 0]}})
    assert named.camera.position == (0.0, 0.0, 9.0)


def _patch_glb(path, edit):
    """Rewrite a .glb's JSON chunk through ``edit(doc)`` (its binary chunk kept)."""
    data = path.read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    rest = data[20 + n:]
    edit(doc)
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + rest
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)


def test_gltf_material_extensions_make_glass_and_bright_lamps(tmp_path):
    glass = PBRMaterial(name="glass", baseColorFactor=[255, 255, 255, 255], metallicFactor=0.0, roughnessFactor=0.0)
    lamp = PBRMaterial(name="lamp", baseColorFactor=[0, 0, 0, 255], emissiveFactor=[1, 0.5, 0.25])
    trimesh.Scene({"g": _quad(0.0, glass), "l": _quad(2.0, lamp)}).export(tmp_path / "s.glb")

    def edit(doc):
        for m in doc["materials"]:
            if m["name"] == "glass":
                m["extensions"] = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                   "KHR_materials_ior": {"ior": 1.45}}
            if m["name"] == "lamp":
                m["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": 8.0}}
    _patch_glb(tmp_path / "s.glb", edit)
    scene = oclgi.load_dict({"mesh": [{"path": str(tmp_path / "s.glb")}]})
    by_name = {m.name.split(":")[-1]: m for m in scene.materials}
    assert by_name["glass"].kind == "dielectric" and by_name["glass"].ior == pytest.approx(1.45)
    np.testing.assert_allclose(by_name["lamp"].emission, [8.0, 4.0, 2.0], rtol=1e-6)
