"""Two-level scenes: movable objects are instances over their own BVH.

A move changes one instance record (transform, world box) and the world
normals of its triangles; ray queries must then equal brute force against
the moved geometry, and moving back must restore every result bit for bit.
"""

import numpy as np
import pyopencl as cl
import pytest
from analytic_scenes import box_mesh as _box

import oclgi
from oclgi.accel.bvh import any_hits, closest_hits
from reference import ray_triangle_brute


def _scene(scenes_dir):
    room_v, room_f = _box((-2, 0, -2), (2, 3, 2))
    light_v = np.array([[-0.3, 2.9, -0.3], [0.3, 2.9, -0.3], [0.3, 2.9, 0.3], [-0.3, 2.9, 0.3]])
    return oclgi.load_dict({
        "mesh": [
            {"path": str(scenes_dir / "stanford-bunny" / "bun_zipper.ply"), "movable": True, "name": "bunny",
             "transform": {"scale": 5.0, "translate": [0, 0.2, 0]}, "albedo": [0.7, 0.7, 0.7]},
            {"vertices": room_v, "faces": room_f, "albedo": [0.6, 0.6, 0.6]},
            {"vertices": light_v, "faces": np.array([[0, 1, 2], [0, 2, 3]]), "emission": [10, 10, 10],
             "albedo": [0, 0, 0]},
        ],
        "camera": {"position": [0, 1.2, 1.9], "look_at": [0, 0.6, 0], "fov": 60, "width": 24, "height": 24},
        "photons": {"count": 20_000, "seed": 9, "max_depth": 8},
    })


def _rigid(rng, shift=0.5):
    a = rng.normal(size=3)
    a /= np.linalg.norm(a)
    angle = rng.uniform(0, 2 * np.pi)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    m[:3, 3] = rng.uniform(-shift, shift, 3)
    return m


@pytest.fixture(scope="module")
def engine(scenes_dir):
    return oclgi.Engine(_scene(scenes_dir))


def test_objects_are_grouped_static_first(engine):
    scene = engine.scene
    assert [o.name for o in scene.objects] == ["static", "bunny"]
    ranges = scene.object_ranges()
    assert ranges[0, 0] == 0 and ranges[-1, 1] == scene.n_triangles
    assert ranges[1, 1] - ranges[1, 0] == 69_451  # the bunny, whole


def _moved_triangles(engine, m):
    scene = engine.scene
    v = scene.vertices[scene.faces].copy()
    a, b = scene.object_ranges()[scene.object_id("bunny")]
    v[a:b] = v[a:b] @ m[:3, :3].T + m[:3, 3]
    return v


def test_moved_object_equals_brute_force(engine, rng):
    m = _rigid(rng)
    m[:3, 3] += [0.2, 0.3, -0.1]
    engine.move("bunny", m)
    try:
        tri_v = _moved_triangles(engine, m)
        a, b = engine.scene.object_ranges()[1]
        # rays aimed at the moved bunny's surface from around the room
        n = 1500
        pick = rng.integers(a, b, n)
        targets = np.einsum("rk,rkc->rc", rng.dirichlet([1, 1, 1], n), tri_v[pick])
        origins = rng.uniform([-1.8, 0.1, -1.8], [1.8, 2.8, 1.8], (n, 3))
        dirs = targets - origins
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        t, _u, _v, tri = closest_hits(engine.queue, engine.compiled, origins, dirs)
        t_ref, tri_ref = ray_triangle_brute(origins, dirs, tri_v)
        assert (tri_ref >= a).sum() > 0.5 * n  # most rays do reach the bunny
        assert ((np.abs(t - t_ref) / t_ref) > 1e-4).sum() <= 2 and (tri == tri_ref).mean() > 0.99
        # world normals of the moved triangles follow the rotation
        normals = np.empty((engine.scene.n_triangles, 4), np.float32)
        import pyopencl as cl

        cl.enqueue_copy(engine.queue, normals, engine.compiled.tri_normals)
        expected = engine.scene.triangle_normals()[a:b] @ m[:3, :3].T
        np.testing.assert_allclose(normals[a:b, :3], expected, atol=2e-5)
    finally:
        engine.move("bunny", np.eye(4))


def test_move_back_restores_every_bit(engine, rng):
    pts = engine.camera_points()
    first = engine.irradiance(pts, method="detp", radius=0.1)
    first_impact = engine.irradiance(pts, method="impact")
    for _ in range(3):
        engine.move("bunny", _rigid(rng))
    moved = engine.irradiance(pts, method="detp", radius=0.1)
    assert not np.array_equal(moved.accumulators, first.accumulators)
    engine.move("bunny", np.eye(4))
    assert np.array_equal(engine.irradiance(pts, method="detp", radius=0.1).accumulators, first.accumulators)
    assert np.array_equal(engine.irradiance(pts, method="impact").accumulators, first_impact.accumulators)
    assert np.array_equal(engine.camera_points().positions, pts.positions)


def test_fresh_engine_and_moved_back_share_every_normal(scenes_dir, rng):
    """A movable object's world normals are made on the device at load as
    after any move, so moving back to the loaded pose restores them bit for
    bit (host numpy and device float32 normals differ in the last bits)."""
    engine = oclgi.Engine(_scene(scenes_dir))
    n = len(engine.scene.faces)

    def normals():
        out = np.empty((n, 4), np.float32)
        cl.enqueue_copy(engine.queue, out, engine.compiled.tri_normals)
        return out

    first = normals()
    engine.move("bunny", _rigid(rng))
    assert not np.array_equal(normals(), first)
    engine.move("bunny", np.eye(4))
    assert normals().tobytes() == first.tobytes()


def test_placing_an_object_at_its_reported_pose_changes_no_bit(scenes_dir, rng):
    """An object placed at the matrix its pose reports (a page's synced pose,
    a checkpoint's) has the record it had, its inverse and box included: the
    record is made from the float32 transform it keeps."""
    engine = oclgi.Engine(_scene(scenes_dir))
    engine.move("bunny", _rigid(rng))
    pose = engine.compiled.pose
    obj = engine.scene.object_id("bunny")
    before = pose.instances_host.tobytes()
    engine.move("bunny", pose.matrix(obj))
    assert pose.instances_host.tobytes() == before


def test_bad_moves(engine):
    with pytest.raises(oclgi.OclgiError, match="no movable object named 'teapot'"):
        engine.move("teapot", np.eye(4))
    with pytest.raises(oclgi.OclgiError, match="singular"):
        engine.move("bunny", np.diag([1.0, 0.0, 1.0, 1.0]))
    with pytest.raises(oclgi.OclgiError, match="finite affine"):
        engine.move("bunny", np.full((4, 4), np.nan))


def test_movable_emitter_is_refused():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    with pytest.raises(oclgi.OclgiError, match="moving lights are not supported"):
        oclgi.load_dict({"mesh": [{"vertices": v, "faces": [[0, 1, 2]], "emission": [1, 1, 1], "movable": True}]})


def test_many_instances_grouped_equal_one_by_one(rng):
    """Past a few instances the top level tests their boxes 8 at a time
    (kernels/bvh.h scene_traverse, oclgi/scene/instance_boxes.py). With 13
    movable boxes (two groups, the second partial), some moved: the hits
    equal brute force, and equal a build that tests the boxes one by one,
    bit for bit, any-hit included; a static-only instance list (a camera
    session's static layer) groups its own boxes."""
    room_v, room_f = _box((-3, 0, -3), (3, 3, 3))
    meshes = [{"vertices": room_v, "faces": room_f[:, ::-1], "albedo": [0.5, 0.5, 0.5]}]  # facing in
    centres = rng.uniform([-2.5, 0.3, -2.5], [2.5, 2.4, 2.0], (13, 3))

    def turned(k):  # a rigid move of box k about its own centre, staying in the room
        m, c = _rigid(rng, 0.3), centres[k]
        m[:3, 3] += c - m[:3, :3] @ c
        return m

    for k in range(13):
        c = centres[k]
        v, f = _box(c - 0.2, c + 0.2)
        meshes.append({"vertices": v, "faces": f, "movable": True, "name": f"box{k}", "albedo": [0.5, 0.5, 0.5]})
    engine = oclgi.Engine(oclgi.load_dict({
        "mesh": meshes, "point_light": [{"position": [0, 2.9, 0], "intensity": [1, 1, 1]}],
        "camera": {"position": [0, 1.5, 2.9], "look_at": [0, 1.2, 0], "fov": 80, "width": 32, "height": 32}}))
    for k in (0, 7, 8, 12):  # both groups, the last lane of the first, the partial second
        engine.move(f"box{k}", turned(k))
    scene = engine.scene
    tri_v = scene.vertices[scene.faces].astype(np.float64)
    for name in (f"box{k}" for k in range(13)):
        a, b = scene.object_ranges()[scene.object_id(name)]
        m = engine.compiled.pose.matrix(scene.object_id(name))
        tri_v[a:b] = tri_v[a:b] @ m[:3, :3].T + m[:3, 3]
    n = 4000
    origins = rng.uniform(-2.9, 2.9, (n, 3)) + [0, 1.5, 0]
    origins[:, 1] = np.clip(origins[:, 1], 0.05, 2.95)
    first_box = scene.object_ranges()[1][0]
    pick = rng.integers(first_box, len(tri_v), n // 2)  # half the rays aimed at the boxes
    targets = np.einsum("rk,rkc->rc", rng.dirichlet([1, 1, 1], n // 2), tri_v[pick])
    dirs = np.concatenate([targets - origins[:n // 2], rng.normal(size=(n - n // 2, 3))])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t, u, v, tri = closest_hits(engine.queue, engine.compiled, origins, dirs)
    t_ref, tri_ref = ray_triangle_brute(origins, dirs, tri_v)
    assert (tri_ref >= first_box).sum() > 0.3 * n and (tri >= 0).all()
    assert (np.abs(t - t_ref) / t_ref > 1e-4).sum() <= 2 and (tri == tri_ref).mean() > 0.995

    never = {"scene_flat_instances": 1000}  # a build that tests the boxes one by one
    t1, u1, v1, tri1 = closest_hits(engine.queue, engine.compiled, origins, dirs, defines=never)
    one_by_one = np.stack([t1, u1, v1, tri1.view(np.float32)], axis=1)
    grouped = np.stack([t, u, v, tri.view(np.float32)], axis=1)
    assert np.array_equal(one_by_one.view(np.int32), grouped.view(np.int32))
    half = np.where(tri >= 0, t * 0.5, 1.0).astype(np.float32)
    assert np.array_equal(any_hits(engine.queue, engine.compiled, origins, dirs, half, defines=never),
                          any_hits(engine.queue, engine.compiled, origins, dirs, half))

    # the static layer's instance list (incremental/dynamic_view.py) holds the room alone
    s = oclgi.Session(engine, method="detp_disc_index", photons=4000, radius=0.2, count_emitted=True)
    before = s.irradiance().copy()
    assert (before > 0).any(axis=1).mean() > 0.5
    m3 = turned(3)
    s.move("box3", m3)
    engine.move("box3", m3)  # a session owns its pose: the engine's moves apart
    fresh = oclgi.Session(engine, method="detp_disc_index", photons=4000, radius=0.2, count_emitted=True)
    assert np.array_equal(s.accumulators(), fresh.accumulators()) and not np.array_equal(before, s.irradiance())
