"""Adaptive DETP radii (``radius_mode="adaptive"``, oclgi/estimators/adaptive_radius.py).

- The radii are a pure function of each point: the same for any work-group
  size, batch split or subset of points, bit for bit.
- Plain DETP with per-point radii is the oracle of disc indexing: the
  accumulators are identical (as tests/test_detp_disc_index.py checks for
  one radius).
- A session keeps its first frame's radii and stays exact: after moves its
  sums equal a recomputation at the final pose with those radii.
- The surface patches cap a radius at the distance to the patch's boundary.
- On the point light over a plane (tests/analytic_scenes.py) the adaptive
  estimate reads the mean irradiance over each point's own disc (its bias,
  like fixed DETP's, is that of the disc mean) within the noise of its
  photons, and at the bright centre its smaller discs blur less than the
  fixed disc.
- Bad options give one error line.
"""

import inspect
import math

import numpy as np
import pytest

import oclgi
from analytic_scenes import box_mesh, disc_mean, exact, grid, ring_points
from exactness import DETP_PHOTONS, surface_points, surface_samples
from oclgi.cli import _method_list
from oclgi.errors import OclgiError
from oclgi.estimators.base import DetpEstimator
from oclgi.estimators.radius_options import DEFAULTS
from oclgi.estimators.surface_patches import SurfacePatches
from oclgi.queries import QueryPoints
from oclgi.study import Config, run_study
from test_session import _moves, _points, _scene

ADAPTIVE = dict(radius_mode="adaptive")


def on_triangles(p, nrm, tri) -> QueryPoints:
    """Query points that know their triangle (the geometric cap needs it)."""
    pos = np.zeros((len(p), 4), np.float32)
    pos[:, :3] = p
    pos[:, 3] = np.asarray(tri, np.int32).view(np.float32)
    n = np.zeros((len(p), 4), np.float32)
    n[:, :3] = nrm
    return QueryPoints(pos, n, np.zeros((len(p), 2), np.float32))


@pytest.fixture(scope="module")
def adaptive_points(engines):
    """As exactness.surface_points, with each point's triangle."""
    rng = np.random.default_rng(77)
    return {name: on_triangles(*surface_samples(e, 600, rng)) for name, e in engines.items()}


def _estimator(engine, pts, method="detp_disc_index", frac=0.01, **options):
    p = engine.run_params(method, DETP_PHOTONS, frac * engine.scene.diagonal)
    return engine.estimator(pts, p, **dict(ADAPTIVE, **options))


def test_radii_capped_and_varied(engines, adaptive_points):
    """The radii lie in [floor, d], and both the density and the geometry bite."""
    e = engines["cornell"]
    d = 0.01 * e.scene.diagonal
    r = _estimator(e, adaptive_points["cornell"]).radii
    assert (r > 0).all() and (r <= d * (1 + 1e-12)).all()
    assert (r < 0.9 * d).mean() > 0.1, "the radii should adapt somewhere"
    assert len(np.unique(r)) > len(r) // 4


# 1 and 7 against the launches' own size (64 where they name none: every other test runs it); 64 itself in the full suite
@pytest.mark.parametrize("local_size", [1, 7, pytest.param(64, marks=pytest.mark.full)])
def test_radii_do_not_depend_on_work_group_or_subset(engines, adaptive_points, local_size):
    e = engines["bunny"]
    pts = adaptive_points["bunny"]
    ref = _estimator(e, pts).radii
    assert np.array_equal(_estimator(oclgi.Engine(e.scene, local_size=local_size), pts).radii, ref)
    sub = np.arange(0, len(pts), 3)
    assert np.array_equal(_estimator(e, pts.subset(sub)).radii, ref[sub])


def test_sums_do_not_depend_on_batch_split(engines, adaptive_points):
    e = engines["cornell"]
    pts = adaptive_points["cornell"]
    d = 0.01 * e.scene.diagonal
    one = e.irradiance(pts, method="detp_disc_index", radius=d, photons=DETP_PHOTONS, **ADAPTIVE)
    small = oclgi.Engine(e.scene, batch_bytes=1 << 20)  # many batches
    many = small.irradiance(pts, method="detp_disc_index", radius=d, photons=DETP_PHOTONS, **ADAPTIVE)
    assert np.array_equal(one.accumulators, many.accumulators)
    assert np.array_equal(one.irradiance, many.irradiance)


@pytest.mark.parametrize("count_emitted", [True, False])
@pytest.mark.parametrize("frac", [0.01, 0.1])
@pytest.mark.parametrize("scene", ["cornell", "bunny"])
def test_disc_index_same_as_plain(engines, adaptive_points, scene, frac, count_emitted):
    e = engines[scene]
    pts = adaptive_points[scene]
    d = frac * e.scene.diagonal
    kw = dict(radius=d, photons=DETP_PHOTONS, count_emitted=count_emitted, **ADAPTIVE)
    plain = e.irradiance(pts, method="detp", **kw)
    fast = e.irradiance(pts, method="detp_disc_index", **kw)
    assert plain.accumulators.any()
    diff = np.nonzero((plain.accumulators != fast.accumulators).any(axis=1))[0]
    assert len(diff) == 0, f"{len(diff)} points differ from plain DETP (first {diff[:5].tolist()})"
    assert np.array_equal(plain.irradiance, fast.irradiance)


def test_resolve_divides_by_each_points_disc(engines, adaptive_points):
    e = engines["cornell"]
    pts = adaptive_points["cornell"]
    est = _estimator(e, pts, method="detp")
    run = oclgi.Engine.run(e, pts, method="detp", radius=0.01 * e.scene.diagonal, photons=DETP_PHOTONS, **ADAPTIVE)
    got = run.complete(None)
    expect = got.accumulators[:, 0] / (got.scale * math.pi * est.radii**2)
    np.testing.assert_allclose(got.irradiance[:, 0], expect, rtol=2e-6)


@pytest.fixture(scope="module")
def moving(scenes_dir):
    return oclgi.Engine(_scene(scenes_dir))


@pytest.mark.parametrize("method", ["detp_disc_index", "detp"])
def test_session_exact_with_first_frame_radii(moving, method):
    rng = np.random.default_rng(5)
    pts = _points(moving, rng, 200)
    moving.move("bunny", np.eye(4))
    session = oclgi.Session(moving, pts, method=method, radius=0.05, **ADAPTIVE)
    radii = session.estimator.radii.copy()
    assert (radii < 0.05).any()
    for m in _moves(rng, 6):
        session.move("bunny", m)
    assert np.array_equal(session.estimator.radii, radii), "the radii stay those of the first frame"
    fresh = oclgi.Session(session.engine, pts, method=method, radius=0.05, radii=radii, **ADAPTIVE)
    assert np.array_equal(session.accumulators(), fresh.accumulators())
    assert np.array_equal(session.irradiance(), fresh.irradiance())
    moving.move("bunny", np.eye(4))


def _boundary_distance_reference(patches, x, tri):
    """Every point against every boundary edge of its patch, float64 (numpy)."""
    out = np.full(len(x), np.inf)
    for i, (p, t) in enumerate(zip(np.asarray(x, np.float64), tri)):
        if t < 0:
            continue
        patch = patches.label[t]
        e = patches.edges[patches.offsets[patch]:patches.offsets[patch + 1]]
        if len(e):
            a, ab = e[:, 0], e[:, 1] - e[:, 0]
            s = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
            out[i] = np.linalg.norm(p - (a + s[:, None] * ab), axis=1).min()
    return out


def test_patches_and_boundary_distance(cl_env):
    """A unit cube: six patches (faces 90 degrees apart); a finely cut square
    is one patch whatever its tessellation; distances to the boundary (the
    device's float32, kernels/surface_patches.cl)."""
    _, queue = cl_env
    v, f = grid(8, 1.0)  # a 2 x 2 square, 128 triangles
    patches = SurfacePatches(v, f)
    assert patches.n_patches == 1 and len(patches.edges) == 4 * 8
    x = np.array([[0.0, 0, 0], [0.9, 0, 0], [0.5, 0, -0.7]])
    tri = np.zeros(3, np.int64)
    np.testing.assert_allclose(patches.boundary_distance(queue, x, tri), [1.0, 0.1, 0.3], atol=1e-6)
    cube = SurfacePatches(*box_mesh((0, 0, 0), (1, 1, 1)))
    assert cube.n_patches == 6
    assert cube.boundary_distance(queue, np.array([[0.5, 0.5, 0.0]]), np.array([0]))[0] == pytest.approx(0.5)


def test_boundary_distance_against_a_float64_reference(cl_env, rng):
    """The device's distances equal every-edge float64 ones on a mesh of many
    patches (a cube, a fine square, a bent strip), points on random
    triangles and some on none."""
    _, queue = cl_env
    v1, f1 = grid(12, 1.5)
    cube_v, cube_f = box_mesh((3, 0.2, 0), (4, 1.2, 1))
    strip_v = np.array([[x, 0.3 * np.sin(x), z] for x in np.linspace(-2, 2, 9) for z in (4.0, 5.0)])
    strip_f = np.array([t for i in range(8) for t in ((2 * i, 2 * i + 1, 2 * i + 3), (2 * i, 2 * i + 3, 2 * i + 2))])
    v = np.concatenate([v1, cube_v, strip_v])
    f = np.concatenate([f1, cube_f + len(v1), strip_f + len(v1) + len(cube_v)])
    patches = SurfacePatches(v, f)
    assert patches.n_patches >= 8
    tri = rng.integers(-1, len(f), 500)
    b = rng.dirichlet([1, 1, 1], 500)
    x = np.einsum("rk,rkc->rc", b, v[f[np.maximum(tri, 0)]])
    got = patches.boundary_distance(queue, x, tri)
    want = _boundary_distance_reference(patches, x, tri)
    assert np.array_equal(np.isinf(got), np.isinf(want)) and np.isinf(got).any()
    fin = np.isfinite(want)
    np.testing.assert_allclose(got[fin], want[fin], rtol=1e-5, atol=1e-6)


def test_point_light_plane_adaptive(plane):
    """The adaptive estimate reads the mean irradiance over each point's own
    disc: within 8% at each point (its discs hold >= ~1,500 photons at 10^6,
    so 3 standard errors are below 8%) and 2% on average; at the five
    central points, where the density is highest, its smaller discs are
    nearer the point value than the fixed disc's mean (which reads 4% low)."""
    d = 0.25
    pts, _ = ring_points()
    scene = plane.scene
    v = scene.vertices[scene.faces]
    tri = np.array([_triangle_under(v, x, z) for x, _, z in pts])
    qp = on_triangles(pts, np.tile([0.0, 1.0, 0.0], (len(pts), 1)), tri)
    est = plane.irradiance(qp, method="detp_disc_index", radius=d, **ADAPTIVE)
    radii = plane.estimator(qp, plane.run_params("detp_disc_index", None, d), **ADAPTIVE).radii
    assert (radii[:5] < 0.6 * d).all(), "the centre is denser than the mean: smaller discs"
    e = est.irradiance[:, 0]
    ref = np.array([disc_mean(x, z, r) for (x, _, z), r in zip(pts, radii)])
    assert np.abs(e / ref - 1).max() < 0.08 and abs(np.mean(e / ref) - 1) < 0.02
    point = exact(pts[:, 0], pts[:, 2])
    fixed = plane.irradiance(qp, method="detp_disc_index", radius=d).irradiance[:, 0]
    assert abs(np.mean(e[:5] / point[:5]) - 1) < abs(np.mean(fixed[:5] / point[:5]) - 1)


def _triangle_under(v, x, z):
    """The triangle of the y = 0 grid that holds (x, z)."""
    a, b, c = v[:, 0][:, [0, 2]], v[:, 1][:, [0, 2]], v[:, 2][:, [0, 2]]
    p = np.array([x, z])

    def cross(u, w):
        return u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]

    s1, s2, s3 = cross(b - a, p - a), cross(c - b, p - b), cross(a - c, p - c)
    inside = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    return int(np.nonzero(inside)[0][0])


@pytest.mark.parametrize("method, options, problem", [
    ("detp_disc_index", dict(radius_mode="wide"), r"^radius_mode must be one of 'fixed', 'adaptive', got 'wide'$"),
    ("detp", dict(radius_mode="adaptive", adaptive_k=1), r"^adaptive_k must be an integer in 2\.\.256, got 1$"),
    ("detp", dict(radius_mode="adaptive", pilot_photons=10), r"^pilot_photons must be an integer in 1024\.\."),
    ("detp", dict(radius_mode="adaptive", radius_min=0), r"^radius_min must be a number in \(0, 1\], got 0$"),
    ("detp", dict(radius_mode="adaptive", radius_min="x"), r"^radius_min must be a number in \(0, 1\]"),
    ("detp", dict(radii=[1.0] * 4), r"^radii are given with radius_mode 'adaptive' only$"),
    ("detp", dict(radius_mode="adaptive", radii=[1.0]), r"^radii must be 4 positive finite numbers"),
    ("detp", dict(radius_mode="adaptive", radii=[1.0, 0, 1, 1]), r"^radii must be 4 positive finite numbers"),
    ("detp_sphere_cache", dict(radius_mode="adaptive"),
     r"^radius_mode 'adaptive' is offered by detp and detp_disc_index, not detp_sphere_cache$"),
])
def test_bad_options_one_line(engines, method, options, problem):
    e = engines["cornell"]
    pts = surface_points(e, 4, np.random.default_rng(1))
    with pytest.raises(OclgiError, match=problem) as info:
        e.irradiance(pts, method=method, photons=2000, **options)
    assert "\n" not in str(info.value)


def test_camera_session_refuses_adaptive(engines):
    with pytest.raises(OclgiError, match=r"^radius_mode 'adaptive' needs a session over given points"):
        oclgi.Session(engines["cornell"], None, method="detp_disc_index", photons=2000, **ADAPTIVE)


def test_study_runs_the_adaptive_variant(plane):
    """``oclgi study --methods detp_disc_index:radius_mode=adaptive``: the
    method syntax gives the option, and the study runs it next to the fixed
    radius, labelled apart."""
    methods = _method_list("detp_disc_index,detp_disc_index:radius_mode=adaptive")
    assert methods == [("detp_disc_index", {}), ("detp_disc_index", {"radius_mode": "adaptive"})]
    configs = [Config(m, [20_000], radius=0.25, **o) for m, o in methods]
    pts = np.array([[x, 0.0, z, 0, 1, 0] for x in (-0.5, 0.0, 0.5) for z in (-0.5, 0.5)])
    result = run_study(plane, configs, points=pts, seeds=2, reference=lambda p, n: exact(p[:, 0], p[:, 2]))
    labels = {row.label for row in result.rows}
    assert len(labels) == 2 and any("radius_mode=adaptive" in label for label in labels)


def test_option_defaults_agree():
    """The engine traces the pilot with radius_options.DEFAULTS: they are the signature's."""
    sig = inspect.signature(DetpEstimator.__init__).parameters
    assert {k: sig[k].default for k in DEFAULTS} == DEFAULTS
