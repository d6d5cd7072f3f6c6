"""The tessellated scene (oclgi/scene/tessellate.py) and sessions over its
vertices, whose points on a movable object follow it
(oclgi/incremental/attached_points.py)."""

import numpy as np
import pytest

import oclgi
from oclgi.scene.tessellate import MAX_VERTICES, tessellate
from test_session import _in_view, _scene


def _areas(v, f):
    t = v[f]
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


@pytest.mark.parametrize("edge", [0.05, 0.2, 1.0])
def test_tessellation_covers_each_triangle_with_short_edges(scenes_dir, edge):
    scene = oclgi.load_file(scenes_dir / "cornell_box.toml")
    t = tessellate(scene, edge)
    v, f = t.vertices, t.faces
    assert np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2).max() <= edge * (1 + 1e-9)
    # the pieces of each triangle add up to it, and face the same way
    src_area = scene.triangle_areas()
    np.testing.assert_allclose(np.bincount(t.face_source, _areas(v, f), len(src_area)), src_area, rtol=1e-9)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.einsum("ij,ij->i", n, scene.triangle_normals()[t.face_source]) > 0).all()
    # each vertex lies on its source triangle at its barycentrics
    sv = scene.vertices[scene.faces[t.vertex_tri]]
    b = t.vertex_barys
    at = sv[:, 0] + b[:, :1] * (sv[:, 1] - sv[:, 0]) + b[:, 1:] * (sv[:, 2] - sv[:, 0])
    np.testing.assert_allclose(at, v, atol=1e-9 * scene.diagonal)
    again = tessellate(scene, edge)
    assert np.array_equal(again.vertices, v) and np.array_equal(again.faces, f)  # deterministic


def test_welding_keeps_creases_and_materials_apart(scenes_dir):
    """A flat square of two triangles cut m x m: (m+1)^2 vertices, shared
    along the diagonal. The Cornell box: its walls meet at right angles, so
    no vertex is shared by two walls. The bunny (smooth): its own vertex
    count, nearly (one per corner would be three times as many)."""
    quad = oclgi.load_dict({"mesh": [{"vertices": [[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]],
                                      "faces": [[0, 2, 1], [0, 3, 2]], "emission": [1, 1, 1]}]})
    t = tessellate(quad, 0.25)  # the diagonal's sqrt(2) sets m = 6
    assert len(t.vertices) == 7 * 7
    box = oclgi.load_file(scenes_dir / "cornell_box.toml")
    t = tessellate(box, 0.5)
    face_n = box.triangle_normals()[t.face_source]  # every face at a vertex has about its orientation
    for k in range(3):
        assert (np.einsum("ij,ij->i", face_n, t.normals[t.faces[:, k]]) > np.cos(np.radians(30))).all()
    bunny = _scene(scenes_dir)
    t = tessellate(bunny, 10.0)  # no cuts: corners welded only
    a, b = bunny.object_ranges()[1]
    used = len(np.unique(bunny.faces[a:b]))
    assert used <= np.count_nonzero((t.vertex_tri >= a) & (t.vertex_tri < b)) < 1.15 * used


def test_bad_edges_are_refused(scenes_dir):
    scene = oclgi.load_file(scenes_dir / "cornell_box.toml")
    for edge in (0.0, -1.0, float("nan")):
        with pytest.raises(oclgi.OclgiError, match="edge length must be a positive number"):
            tessellate(scene, edge)
    with pytest.raises(oclgi.OclgiError, match=f"at most {MAX_VERTICES:,}"):
        tessellate(scene, 1e-4)


@pytest.mark.parametrize("method", ["detp_disc_index", "impact"])
def test_a_session_over_vertices_moves_the_objects_points(scenes_dir, rng, method):
    """The vertices on the bunny follow it; after moves every vertex's sums
    equal a fresh session over the points where they are now, and plain
    DETP; back at the start, the first frame's sums and points."""
    engine = oclgi.Engine(_scene(scenes_dir))
    pts = tessellate(engine.scene, 0.25).points()
    s = oclgi.Session(engine, pts, method=method, photons=10_000, radius=0.05)
    first = s.accumulators()
    a, b = engine.scene.object_ranges()[1]
    on = (pts.tri >= a) & (pts.tri < b)
    assert on.sum() > 1000 and (~on).sum() > 100
    for m in _in_view(rng, 5):
        stats = s.move("bunny", m)
    assert stats.points == on.sum()
    moved = pts.positions[on, :3].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    np.testing.assert_allclose(s.points.positions[on, :3], moved, atol=1e-5)
    np.testing.assert_array_equal(s.points.positions[~on], pts.positions[~on])
    fresh = oclgi.Session(s.engine, s.points.copy(), method=method, photons=10_000, radius=0.05)
    assert np.array_equal(s.accumulators(), fresh.accumulators())
    if method == "detp_disc_index":
        plain = s.engine.irradiance(s.points.copy(), method="detp", photons=10_000, radius=0.05)
        assert np.array_equal(s.accumulators(), plain.accumulators)
    s.move("bunny", np.eye(4))
    assert np.array_equal(s.accumulators(), first) and s.points.positions.tobytes() == pts.positions.tobytes()
