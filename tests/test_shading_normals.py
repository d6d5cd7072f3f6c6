"""Shading normals (oclgi/scene/shading_normals.py, kernels/shading_normals.h):
vertex normals read per corner from OBJ vn, glTF and PLY; camera points
take them (discs lifted in front of their triangle), so a sphere mesh
renders without facets and its irradiance comes closer to the smooth
sphere's; meshes without them, and smooth = false, are what they were."""

import io

import numpy as np
import pytest
import trimesh

import oclgi
from oclgi.errors import OclgiError
from oclgi.scene.obj import read_obj

LIGHT = np.array([1.2, 1.2, 1.2])  # a point light of 1 W/sr near a unit sphere at the origin
SIDE = 48
RADIUS = 0.05


def uv_sphere(nu=16, nv=8):
    """A unit UV sphere (outward winding) and its exact normals (the vertices)."""
    th, ph = np.linspace(0, np.pi, nv + 1), np.linspace(0, 2 * np.pi, nu + 1)[:-1]
    v = [[0, 1, 0]] + [[np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)] for t in th[1:-1] for p in ph]
    v.append([0, -1, 0])
    ring = lambda k, j: 1 + k * nu + (j % nu)  # noqa: E731
    f = [[0, ring(0, j + 1), ring(0, j)] for j in range(nu)]
    for k in range(nv - 2):
        for j in range(nu):
            f += [[ring(k, j), ring(k, j + 1), ring(k + 1, j + 1)], [ring(k, j), ring(k + 1, j + 1), ring(k + 1, j)]]
    last = len(v) - 1
    f += [[last, ring(nv - 3, j), ring(nv - 3, j + 1)] for j in range(nu)]
    return np.array(v, np.float64), np.array(f)


def sphere_obj(path, normals=True):
    v, f = uv_sphere()
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v]
    if normals:
        lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v]
        lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in f]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    path.write_text("\n".join(lines) + "\n")
    return path


def sphere_scene(path, smooth=True, **mesh):
    return oclgi.load_dict({
        "mesh": [{"path": str(path), "albedo": [0.5] * 3, "smooth": smooth, **mesh}],
        "point_light": [{"position": list(LIGHT), "intensity": [1, 1, 1]}],
        "camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "fov": 35, "width": SIDE, "height": SIDE},
        "photons": {"count": 1_000_000, "seed": 1, "max_depth": 2}, "estimator": {"radius": RADIUS}})


@pytest.fixture(scope="module")
def spheres(tmp_path_factory):
    d = tmp_path_factory.mktemp("spheres")
    return sphere_obj(d / "smooth.obj"), sphere_obj(d / "flat.obj", normals=False)


def neighbour_angles(points):
    """Degrees between the normals of horizontally neighbouring pixels, both on the sphere."""
    n = points.normals[:, :3].reshape(SIDE, SIDE, 3).astype(np.float64)
    hit = (points.tri >= 0).reshape(SIDE, SIDE)
    both = hit[:, 1:] & hit[:, :-1]
    return np.degrees(np.arccos(np.clip((n[:, 1:] * n[:, :-1]).sum(-1), -1, 1)))[both]


def exact_deviation(points):
    """Degrees between each sphere pixel's normal and the unit sphere's own there."""
    hit = points.tri >= 0
    x = points.positions[hit, :3].astype(np.float64)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip((x * points.normals[hit, :3]).sum(1), -1, 1)))


def sphere_errors(engine, lift=RADIUS):
    """Relative errors of the camera points' irradiance against the smooth
    unit sphere's, E = I cos / r^2 at the point's direction from the centre
    (direct light only: a convex sphere cannot light itself), where cos > 0.3."""
    pts = engine.camera_points(lift=lift)
    e = engine.irradiance(pts).irradiance[:, 0]
    x = pts.positions[:, :3].astype(np.float64)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    r = LIGHT - x
    dist = np.linalg.norm(r, axis=1)
    cos = (x * r).sum(1) / dist
    exact = cos / dist**2
    sel = (pts.tri >= 0) & (cos > 0.3)
    return (e[sel] - exact[sel]) / exact[sel], pts


def test_obj_reads_vn_per_corner(tmp_path):
    f = tmp_path / "quad.obj"
    f.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nvn 0 0.6 0.8\n"
                 "f 1/1/1 2/1/2 3/1/-1 4//-2\nf 1 2 3\n")
    obj = read_obj(f)
    vn = obj.face_normal()
    assert vn.shape == (3, 3, 3)
    np.testing.assert_array_equal(vn[0], [[0, 0, 1], [0, 0.6, 0.8], [0, 0.6, 0.8]])
    np.testing.assert_array_equal(vn[1], [[0, 0, 1], [0, 0.6, 0.8], [0, 0, 1]])  # the fan's second triangle
    assert np.isnan(vn[2]).all()  # a face without normals
    assert obj.face_uv()[0, 0].tolist() == [0, 0]  # texture coordinates read as before
    f.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 1\nf 1//1 2//2 3//1\n")
    with pytest.raises(OclgiError, match=r"quad.obj:5: '2//2' refers to no normal \(vn\)"):
        read_obj(f).face_normal()
    f.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n")
    assert read_obj(f).face_normal() is None


def test_scene_keeps_unit_normals_and_drops_partial_sets(tmp_path):
    f = tmp_path / "two.obj"
    f.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 2\nf 1//1 2//1 3//1\nf 1//1 3 4//1\n")
    desc = {"mesh": [{"path": str(f), "emission": [1, 1, 1]}]}
    vn = oclgi.load_dict(desc).tri_vertex_normals
    np.testing.assert_allclose(vn[0], [[0, 0, 1]] * 3)
    assert np.isnan(vn[1]).all()  # a corner without vn: the triangle keeps its geometric normal
    assert oclgi.load_dict({"mesh": [dict(desc["mesh"][0], smooth=False)]}).tri_vertex_normals is None
    assert oclgi.load_dict(dict(desc, smooth=False)).tri_vertex_normals is None
    with pytest.raises(OclgiError, match=r"mesh\[0\].smooth: expected true or false"):
        oclgi.load_dict({"mesh": [dict(desc["mesh"][0], smooth="no")]})


def test_normals_that_do_not_describe_the_triangle_stay_flat(tmp_path):
    """A corner normal beyond 60 degrees of its face's (a hard edge averaged
    over) leaves the triangle flat; normals all opposing the winding are
    turned round."""
    f = tmp_path / "three.obj"
    f.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 1\nvn 0 0.8 0.6\nvn 0 0.9 0.43589\nvn 0 0 -1\n"
                 "f 1//1 2//1 3//2\nf 1//1 2//1 3//3\nf 1//4 2//4 3//4\n")
    vn = oclgi.load_dict({"mesh": [{"path": str(f), "emission": [1, 1, 1]}]}).tri_vertex_normals
    np.testing.assert_allclose(vn[0, 2], [0, 0.8, 0.6])  # 53 degrees: kept
    assert np.isnan(vn[1]).all()  # 64 degrees: flat
    np.testing.assert_array_equal(vn[2], [[0, 0, 1]] * 3)  # reversed: turned to the face's side


def test_transform_turns_normals(tmp_path):
    """A mesh's transform turns its normals by the inverse transpose (a
    non-uniform scale bends them away from the scaled direction)."""
    f = tmp_path / "tri.obj"
    f.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0.6 0 0.8\nf 1//1 2//1 3//1\n")
    s = oclgi.load_dict({"mesh": [{"path": str(f), "emission": [1, 1, 1], "transform": {"scale": [2, 1, 1]}}]})
    n = np.array([0.3, 0, 0.8])
    np.testing.assert_allclose(s.tri_vertex_normals[0, 0], n / np.linalg.norm(n), rtol=1e-12)


def test_gltf_and_ply_normals():
    m = trimesh.creation.icosphere(subdivisions=1)
    vn = np.asarray(m.vertex_normals)
    for data, kind in ((trimesh.Scene(m).export(file_type="glb", include_normals=True), "glb"),
                       (m.export(file_type="ply", vertex_normal=True), "ply")):
        loaded = trimesh.load(io.BytesIO(data), file_type=kind, process=False, force="scene")
        s = oclgi.load_dict({"mesh": [{"trimesh": loaded, "emission": [1, 1, 1]}]})
        np.testing.assert_allclose(s.tri_vertex_normals, vn[m.faces], atol=1e-6)
    plain = trimesh.load(io.BytesIO(trimesh.creation.icosphere(subdivisions=1).export(file_type="ply")),
                         file_type="ply", process=False, force="scene")
    assert oclgi.load_dict({"mesh": [{"trimesh": plain, "emission": [1, 1, 1]}]}).tri_vertex_normals is None


def test_meshes_without_normals_unchanged(spheres):
    """No vn, or smooth = false: the geometric normal, bit for bit, as the
    camera gave before, and the same image bytes either way."""
    smooth, flat = spheres
    renders = []
    for scene in (sphere_scene(flat), sphere_scene(smooth, smooth=False)):
        engine = oclgi.Engine(scene)
        pts = engine.camera_points()
        hit = pts.tri >= 0
        geometric = scene.triangle_normals().astype(np.float32)[pts.tri[hit]]
        towards = np.where(((geometric * pts.normals[hit, :3]).sum(1) < 0)[:, None], -geometric, geometric)
        np.testing.assert_allclose(pts.normals[hit, :3], towards, atol=1e-6)
        assert (engine.compiled.shading_host == 0).all()
        renders.append(engine.render(photons=50_000))
    assert renders[0].pixels.tobytes() == renders[1].pixels.tobytes()
    assert renders[0].radiance.tobytes() == renders[1].radiance.tobytes()


def test_sphere_renders_smooth_and_closer_to_the_exact_irradiance(spheres):
    smooth, flat = spheres
    err_flat, pts_flat = sphere_errors(oclgi.Engine(sphere_scene(flat)))
    err_smooth, pts_smooth = sphere_errors(oclgi.Engine(sphere_scene(smooth)))
    # facets: neighbours share a normal or jump by a facet's angle; smooth: the sphere's own normal
    a_flat, a_smooth = neighbour_angles(pts_flat), neighbour_angles(pts_smooth)
    assert (a_flat == 0).mean() > 0.2 and (a_smooth == 0).mean() < 0.02
    assert a_smooth.max() < 0.75 * a_flat.max()
    dev_flat, dev_smooth = exact_deviation(pts_flat), exact_deviation(pts_smooth)
    assert np.median(dev_flat) > 5 and dev_smooth.max() < 1  # degrees (measured 8.5 and 0.18)
    # the flux through the turned discs: the smooth sphere's irradiance (measured 4% mean error against 14%)
    assert np.abs(err_smooth).mean() < 0.5 * np.abs(err_flat).mean() and abs(err_smooth.mean()) < 0.02
    # the image: the render's normal layer is these normals (its pixels, albedo E / pi at them)
    layer = oclgi.Engine(sphere_scene(smooth)).render(photons=20_000, layers=True).layers["normal"]
    np.testing.assert_array_equal(layer.reshape(-1, 3), pts_smooth.normals[:, :3] * (pts_smooth.tri >= 0)[:, None])


def test_unlifted_discs_would_lose_half_the_light(spheres):
    """Why the camera lifts a turned disc (oclgi/scene/shading_normals.py):
    without it, the half behind the triangle sees no segment."""
    engine = oclgi.Engine(sphere_scene(spheres[0]))
    err, _ = sphere_errors(engine, lift=0.0)
    assert err.mean() < -0.3
    for bad in (-1.0, float("nan"), "0.1", True):
        with pytest.raises(OclgiError, match="lift: expected a disc radius"):
            engine.camera_points(lift=bad)


def test_moved_object_turns_its_shading_normals(spheres, tmp_path):
    """A movable mesh's shading normals follow its instance's transform (the
    kernel turns the object-space normal): moved, it shows the normals of
    the same mesh placed there by the scene file."""
    smooth = spheres[0]
    floor = {"vertices": [[-9, -3, -9], [9, -3, -9], [9, -3, 9], [-9, -3, 9]], "faces": [[0, 2, 1], [0, 3, 2]]}
    base = {"point_light": [{"position": list(LIGHT), "intensity": [1, 1, 1]}],
            "camera": {"position": [0, 0, 4], "look_at": [0, 0, 0], "fov": 35, "width": SIDE, "height": SIDE}}
    angle, shift = 40.0, [0.2, 0.1, -0.3]
    moved = oclgi.Engine(oclgi.load_dict(dict(base, mesh=[floor, {"path": str(smooth), "movable": True,
                                                                     "name": "ball"}])))
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    moved.move("ball", [[c, 0, s, shift[0]], [0, 1, 0, shift[1]], [-s, 0, c, shift[2]], [0, 0, 0, 1]])
    placed = oclgi.Engine(oclgi.load_dict(dict(base, mesh=[floor, {
        "path": str(smooth), "transform": {"rotate": [0, 1, 0, angle], "translate": shift}}])))
    a, b = moved.camera_points(), placed.camera_points()
    on_ball = (a.tri >= 2) & (a.tri == b.tri)  # the floor is object 0 (triangles 0, 1) in both
    assert on_ball.sum() > 500
    np.testing.assert_allclose(a.normals[on_ball, :3], b.normals[on_ball, :3], atol=2e-4)
