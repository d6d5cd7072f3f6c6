"""Small things a user reaches for: paths as pathlib.Path, inline images in
notebooks, the command's version."""

import tomllib

import numpy as np
import pytest
import trimesh
from cli_run import in_process
from small_scene import MOVING_BLOCK
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

import oclgi
from oclgi.io import read_image


def test_a_mesh_path_may_be_a_pathlib_path(scenes_dir):
    as_str = oclgi.load_dict({"mesh": [{"path": str(scenes_dir / "cornell-box" / "CornellBox-Original.obj")}]})
    as_path = oclgi.load_dict({"mesh": [{"path": scenes_dir / "cornell-box" / "CornellBox-Original.obj"}]})
    assert np.array_equal(as_str.vertices, as_path.vertices) and np.array_equal(as_str.faces, as_path.faces)


def test_a_render_shows_inline_as_the_png_it_writes(tmp_path):
    result = oclgi.Engine(oclgi.load_dict(tomllib.loads(MOVING_BLOCK))).render(photons=5_000)
    png = result._repr_png_()
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    path = tmp_path / "inline.png"
    path.write_bytes(png)
    decoded = np.rint(read_image(path) * 255).astype(np.uint8)  # OpenImageIO reads it as floats in 0..1
    assert np.array_equal(decoded, result.pixels)


def test_version(tmp_path, monkeypatch, capsys):
    res = in_process(monkeypatch, capsys, tmp_path, "--version")
    assert res.returncode == 0 and res.stdout.strip() == f"oclgi {oclgi.__version__}"


# A floor and a small emissive quad above it, facing down.
V = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1],
              [-0.2, 1, -0.2], [0.2, 1, -0.2], [0.2, 1, 0.2], [-0.2, 1, 0.2]], np.float64)
F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]])


def _trimesh_scene():
    floor = trimesh.Trimesh(V[:4], F[:2], process=False)
    light = trimesh.Trimesh(V[4:], F[2:] - 4, process=False)
    floor.visual = TextureVisuals(material=PBRMaterial(baseColorFactor=[204, 51, 51, 255]))
    light.visual = TextureVisuals(material=PBRMaterial(baseColorFactor=[0, 0, 0, 255], emissiveFactor=[1, 1, 1]))
    return trimesh.Scene({"floor": floor, "light": light})


def _up_and_down_sums(engine):
    """Sums at points facing up (light from the quad) and facing down (light the floor reflects)."""
    xz = np.array([[x, z] for x in (-0.5, 0.0, 0.5) for z in (-0.5, 0.5)])
    up = np.column_stack([xz[:, 0], np.zeros(6), xz[:, 1]])
    down = np.column_stack([xz[:, 0], np.full(6, 0.5), xz[:, 1]])
    pts = oclgi.query_points(np.vstack([up, down]), np.vstack([np.tile([0.0, 1.0, 0.0], (6, 1)),
                                                               np.tile([0.0, -1.0, 0.0], (6, 1))]))
    return engine.irradiance(pts, photons=20_000, radius=0.1).accumulators


def test_trimesh_objects_and_face_arrays_give_the_file_scenes_bits(tmp_path):
    scene = _trimesh_scene()
    scene.export(tmp_path / "s.glb")
    (tmp_path / "s.toml").write_text('[[mesh]]\npath = "s.glb"\n')
    from_file = _up_and_down_sums(oclgi.Engine(oclgi.load_file(tmp_path / "s.toml")))
    assert from_file[:, 0].sum() > 0
    assert np.array_equal(_up_and_down_sums(oclgi.Engine(scene)), from_file)  # a trimesh Scene straight in
    as_dict = oclgi.load_dict({"mesh": [{"trimesh": scene}]})
    assert np.array_equal(_up_and_down_sums(oclgi.Engine(as_dict)), from_file)
    arrays = oclgi.load_dict({"mesh": [{"vertices": V, "faces": F,
                                        "face_albedo": [[0.8, 0.2, 0.2]] * 2 + [[0.0, 0.0, 0.0]] * 2,
                                        "face_emission": [[0.0, 0.0, 0.0]] * 2 + [[1.0, 1.0, 1.0]] * 2}]})
    assert [m.name for m in arrays.materials] == ["mesh[0].default", "mesh[0]:#0", "mesh[0]:#1"]
    assert np.array_equal(_up_and_down_sums(oclgi.Engine(arrays)), from_file)


def test_a_trimesh_scene_without_a_camera_renders_from_trimeshs_default(recwarn):
    """trimesh gives every Scene a default camera (``Scene.camera``): a
    scene without one renders from it, with a note, and is not changed; a
    scene file without [camera] still says it has none."""
    scene = _trimesh_scene()
    assert not scene.has_camera
    engine = oclgi.Engine(scene)
    assert not scene.has_camera  # the user's scene is left as it was
    cam = engine.scene.camera
    # trimesh's own default camera, computed on a copy: the same eye, axis and fields of view
    ref = scene.copy()
    world = ref.camera_transform
    assert np.allclose(cam.position, world[:3, 3])
    assert np.allclose(np.subtract(cam.look_at, cam.position), -world[:3, 2])
    assert cam.fov == pytest.approx(ref.camera.fov[1]) and cam.height == 256
    across = 2 * np.degrees(np.arctan(np.tan(np.radians(cam.fov) / 2) * cam.width / cam.height))
    assert across == pytest.approx(ref.camera.fov[0], abs=0.2)
    with pytest.warns(oclgi.OclgiWarning, match="trimesh's default"):  # said when it is used
        result = engine.render(photons=5_000, width=24, height=18)
    assert result.radiance.shape == (18, 24, 3) and result.radiance.max() > 0
    # a camera the scene has is used as it is, without a note
    scene.camera_transform = trimesh.transformations.translation_matrix([0.0, 0.5, 4.0])
    recwarn.clear()
    moved = oclgi.Engine(scene).scene.camera
    assert not [w for w in recwarn if "default" in str(w.message)]
    assert np.allclose(moved.position, (0.0, 0.5, 4.0))


def test_face_arrays_are_checked():
    with pytest.raises(oclgi.OclgiError, match=r"face_albedo: expected an \(4, 3\) array"):
        oclgi.load_dict({"mesh": [{"vertices": V, "faces": F, "face_albedo": [[0.5, 0.5, 0.5]]}]})
    with pytest.raises(oclgi.OclgiError, match=r"expected a trimesh Trimesh or Scene, got str"):
        oclgi.load_dict({"mesh": [{"trimesh": "box"}]})


def test_the_summary_stages_add_up_to_the_total(cornell):
    # which stages are reported and how they nest; how long they take is bench/'s
    for method in ("detp_disc_index", "photon_map"):
        stats = cornell.render(method=method, photons=50_000, width=16, height=16).stats
        s = stats.seconds
        assert list(s) == ["load", "setup", "camera", "trace", "estimate", "resolve", "total"]
        assert s["load"] == cornell.scene.load_seconds and s["setup"] == cornell.setup_seconds
        # the run's stages are intervals within its total
        assert s["camera"] + s["trace"] + s["estimate"] + s["resolve"] <= s["total"], s
        engine_part, run_part = stats.summary().split(" | ")[1:]
        assert engine_part.startswith("load ") and run_part.startswith("camera ") and " total " in run_part


def test_vertex_albedo_gives_the_bits_of_the_glb_with_its_colours(tmp_path):
    # 8-bit colours, as a glTF's COLOR_0 holds them after trimesh's export
    rgb8 = np.array([[230, 40, 40], [40, 230, 40], [40, 40, 230], [200, 200, 200]], np.uint8)
    floor = trimesh.Trimesh(V[:4], F[:2], vertex_colors=np.hstack([rgb8, np.full((4, 1), 255, np.uint8)]),
                            process=False)
    light = trimesh.Trimesh(V[4:], F[2:] - 4, process=False)
    light.visual = TextureVisuals(material=PBRMaterial(baseColorFactor=[0, 0, 0, 255], emissiveFactor=[1, 1, 1]))
    trimesh.Scene({"floor": floor, "light": light}).export(tmp_path / "s.glb")
    (tmp_path / "s.toml").write_text('[[mesh]]\npath = "s.glb"\nalbedo = [1, 1, 1]\n')
    scene = oclgi.load_file(tmp_path / "s.toml")
    assert scene.tri_colour is not None  # the file's COLOR_0 reached the scene
    from_file = _up_and_down_sums(oclgi.Engine(scene))
    arrays = oclgi.load_dict({"mesh": [
        {"vertices": V[:4], "faces": F[:2], "vertex_albedo": rgb8 / 255.0},
        {"vertices": V[4:], "faces": F[2:] - 4, "albedo": [0, 0, 0], "emission": [1, 1, 1]}]})
    sums = _up_and_down_sums(oclgi.Engine(arrays))
    assert sums[6:].min() > 0  # the floor's reflection reached the points facing down
    assert np.array_equal(sums, from_file)
    # and the colours matter: a grey floor gives other sums
    grey = oclgi.load_dict({"mesh": [
        {"vertices": V[:4], "faces": F[:2], "albedo": [0.6, 0.6, 0.6]},
        {"vertices": V[4:], "faces": F[2:] - 4, "albedo": [0, 0, 0], "emission": [1, 1, 1]}]})
    assert not np.array_equal(_up_and_down_sums(oclgi.Engine(grey))[6:], sums[6:])


def test_vertex_albedo_is_checked():
    with pytest.raises(oclgi.OclgiError, match=r"vertex_albedo: expected an \(8, 3\) array"):
        oclgi.load_dict({"mesh": [{"vertices": V, "faces": F, "vertex_albedo": [[0.5, 0.5, 0.5]]}]})
    with pytest.raises(oclgi.OclgiError, match=r"vertex_albedo\[2\]: an albedo is linear RGB from 0 to 1"):
        oclgi.load_dict({"mesh": [{"vertices": V, "faces": F,
                                   "vertex_albedo": [[0.5] * 3] * 2 + [[1.5, 0, 0]] + [[0.5] * 3] * 5}]})
    with pytest.raises(oclgi.OclgiError, match=r"vertex_albedo goes with 'vertices' and 'faces'"):
        oclgi.load_dict({"mesh": [{"path": "x.obj", "vertex_albedo": [[0.5] * 3]}]})
