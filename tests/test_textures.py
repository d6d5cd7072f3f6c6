"""Albedo textures: decoding, lookups on the device, photons and images
that follow them, against Mitsuba 3, and exact incremental updates with a
textured object moving."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh
from conftest import SCENES

import oclgi
from oclgi.scene import textures
from oclgi.study import image_compare, mitsuba as mitsuba_reference
from test_instances import _rigid


def write_png(path, pixels_u8):
    out = oiio.ImageOutput.create(str(path))
    h, w, c = pixels_u8.shape
    out.open(str(path), oiio.ImageSpec(w, h, c, oiio.UINT8))
    out.write_image(pixels_u8)
    out.close()


def checker(n=64, cells=4):
    """An n x n sRGB image: red and green cells, and a blue top-left cell
    (so a flip or a turn of the texture shows)."""
    img = np.zeros((n, n, 3), np.uint8)
    k = n // cells
    for y in range(cells):
        for x in range(cells):
            img[y * k:(y + 1) * k, x * k:(x + 1) * k] = (230, 40, 40) if (x + y) % 2 else (40, 200, 40)
    img[:k, :k] = (40, 40, 230)
    return img


def test_integer_images_are_decoded_from_srgb(tmp_path):
    write_png(tmp_path / "grey.png", np.full((2, 3, 3), 128, np.uint8))
    t = textures.read(tmp_path / "grey.png")
    assert t.shape == (2, 3, 3) and t.dtype == np.float32
    np.testing.assert_allclose(t, ((128 / 255 + 0.055) / 1.055) ** 2.4, rtol=1e-6)


def test_uv_maps_are_exact_on_the_triangle(rng):
    v = rng.normal(size=(50, 3, 3))
    uv = rng.random((50, 3, 2)) * 4 - 1
    m = textures.uv_maps(v, uv).astype(np.float64)
    bary = rng.dirichlet([1, 1, 1], 50)
    p = np.einsum("fk,fkc->fc", bary, v)
    want = np.einsum("fk,fkc->fc", bary, uv)
    got = np.stack([(m[:, 0:3] * p).sum(1) + m[:, 3], (m[:, 4:7] * p).sum(1) + m[:, 7]], axis=1)
    np.testing.assert_allclose(got, want, atol=1e-4)


def textured_room(tmp_path, movable=False):
    """The Cornell box with a textured panel standing on its floor (OBJ + MTL + PNG)."""
    write_png(tmp_path / "checker.png", checker())
    (tmp_path / "panel.mtl").write_text("newmtl painted\nKd 1 1 1\nmap_Kd checker.png\n")
    (tmp_path / "panel.obj").write_text(
        "mtllib panel.mtl\n"
        "v -0.6 0.05 -0.5\nv 0.6 0.05 -0.5\nv 0.6 1.25 -0.5\nv -0.6 1.25 -0.5\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "usemtl painted\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    return oclgi.load_dict({
        "mesh": [{"path": str(SCENES / "cornell-box" / "CornellBox-Original.obj")},
                 {"path": str(tmp_path / "panel.obj"), "movable": movable, "name": "panel"}],
        "camera": {"position": [0, 1, 3.94], "look_at": [0, 1, 0], "fov": 39.3, "width": 48, "height": 48},
        "photons": {"count": 20_000, "seed": 3, "max_depth": 10},
    })


def test_the_image_shows_the_texture(tmp_path):
    """The panel's pixels take the texture's colours where they should: blue
    in its top-left cell, red and green alternating."""
    engine = oclgi.Engine(textured_room(tmp_path))
    albedo = engine.render(photons=50_000, radius=0.05, layers=True).layers["albedo"]
    panel = engine.camera_points().tri.reshape(48, 48) >= 36
    lin = textures.srgb_to_linear(np.array([[40, 40, 230], [230, 40, 40], [40, 200, 40]]) / 255)
    # every panel pixel's albedo is one of the three colours, or a blend at a cell's border
    nearest = np.abs(albedo[panel][:, None, :] - lin[None]).max(axis=2).min(axis=1)
    assert (nearest < 1e-3).mean() > 0.6
    # the top-left cell (as the camera sees the panel) is blue
    row = np.nonzero(panel.any(axis=1))[0].min()  # the panel's top edge, above the tall box
    col = np.nonzero(panel[row])[0].min() + 1
    assert panel[row, col]
    np.testing.assert_allclose(albedo[row, col], lin[0], atol=1e-3)


def test_textured_image_agrees_with_mitsuba(tmp_path):
    """The texture's orientation, decoding and the light it reflects (the
    photons scatter with the texture's albedo) against Mitsuba's bitmap."""
    engine = oclgi.Engine(textured_room(tmp_path))
    result = engine.render(width=48, height=48, photons=1_000_000, radius=0.05, seed=1)
    ref = mitsuba_reference.render(engine, width=48, height=48, spp=512, seed=0)
    mask = image_compare.edge_mask(result.estimate.points, 1, scene=engine.scene)
    # the texture's cell borders are edges of the image too
    mask |= image_compare.dilate(np.abs(np.diff(ref.mean(axis=2), axis=1, prepend=0)) > 0.05, 1)
    cmp = image_compare.compare(result.radiance, ref, mask)
    assert cmp.compared > 400, cmp
    assert cmp.rel_median < 0.05, cmp
    assert np.all(np.abs(np.array(cmp.channel_ratio) - 1) < 0.03), cmp


def test_session_with_a_textured_object_moving_equals_recomputation(tmp_path, rng):
    engine = oclgi.Engine(textured_room(tmp_path, movable=True))
    session = oclgi.Session(engine, method="detp_disc_index", radius=0.05, photons=10_000)
    first, _ = session.render()
    for _ in range(5):
        m = _rigid(rng, shift=0.3)
        m[:3, 3] = np.clip(m[:3, 3], -0.3, 0.3)
        session.move("panel", m)
    engine = session.engine  # the session's pose, for the recomputations
    fresh = oclgi.Session(engine, method="detp_disc_index", radius=0.05, photons=10_000)
    assert np.array_equal(session.accumulators(), fresh.accumulators())
    seg, _ = session.segments()
    fresh_seg, _ = engine.trace(10_000, seed=3, max_depth=10)
    seg["power"] *= engine.photon_watts(10_000)
    assert seg.tobytes() == fresh_seg.tobytes() and np.array_equal(session.render()[0], fresh.render()[0])
    session.move("panel", np.eye(4))
    assert np.array_equal(session.render()[0], first)


def test_a_missing_texture_is_one_warning(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl a\nKd 0.5 0.5 0.5\nmap_Kd nowhere.png\n")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                    "usemtl a\nf 1/1 2/2 3/3\n")
    with pytest.warns(oclgi.OclgiWarning, match="nowhere.png.*not found"):
        scene = oclgi.load_dict({"mesh": [{"path": str(tmp_path / "m.obj"), "emission": [1, 1, 1]}]})
    assert all(m.texture is None for m in scene.materials)


def coloured_room(scenes_dir):
    """The Cornell box with a panel whose vertices are coloured (a trimesh
    object with vertex colours, as glTF's COLOR_0 reads)."""
    panel = trimesh.Trimesh(vertices=[[-0.6, 0.05, -0.5], [0.6, 0.05, -0.5], [0.6, 1.25, -0.5], [-0.6, 1.25, -0.5]],
                            faces=[[0, 1, 2], [0, 2, 3]], process=False)
    panel.visual.vertex_colors = np.array([[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [255, 255, 255, 255]],
                                          np.uint8)
    return oclgi.load_dict({
        "mesh": [{"path": str(scenes_dir / "cornell-box" / "CornellBox-Original.obj")},
                 {"trimesh": panel, "albedo": [0.9, 0.9, 0.9]}],
        "camera": {"position": [0, 1, 3.94], "look_at": [0, 1, 0], "fov": 39.3, "width": 48, "height": 48},
    }, base_dir=scenes_dir)


def test_vertex_colours_agree_with_mitsuba(scenes_dir):
    """The panel's colours interpolated across it (and the light it
    reflects in them) against Mitsuba's vertex_color attribute."""
    scene = coloured_room(scenes_dir)
    assert scene.tri_colour is not None and any(m.vertex_colours for m in scene.materials)
    engine = oclgi.Engine(scene)
    result = engine.render(photons=1_000_000, radius=0.05, seed=1, layers=True)
    pts = engine.camera_points()
    panel = (pts.tri >= 36).reshape(48, 48)
    albedo = result.layers["albedo"][panel]
    assert albedo[:, 0].max() > 0.6 and albedo[:, 1].max() > 0.6 and albedo[:, 2].max() > 0.6  # all three corners
    ref = mitsuba_reference.render(engine, spp=512, seed=0)
    mask = image_compare.edge_mask(result.estimate.points, 1, scene=engine.scene)
    cmp = image_compare.compare(result.radiance, ref, mask)
    assert cmp.compared > 400, cmp
    assert cmp.rel_median < 0.05, cmp
    assert np.all(np.abs(np.array(cmp.channel_ratio) - 1) < 0.03), cmp
