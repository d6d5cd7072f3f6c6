"""Final gathering for DETP (``gather = N``, oclgi/estimators/final_gather.py,
kernels/final_gather.cl).

- Analytic: a point light over a diffuse plane of albedo rho, and query
  points facing the plane from above (no geometry there). Their direct
  light is 0 (the light is behind them), the plane's irradiance is the
  closed form (exact direct light at the hits; a plane cannot light
  itself, so the discs add nothing), so the gathered irradiance is
  rho / pi times the plane's irradiance integrated over what the point
  sees, cos-weighted: a float64 quadrature. Final gathering adds no bias
  here, only the stratified rays' noise (measured 0.01% and 0.04% at
  4,096 rays): within 0.5%.
- The gather's resolve against a float64 reference from its own parts
  (the hits' irradiance and weights, the points' direct light), on a scene
  with indirect light at the hits.
- Bit for bit: the same run twice, other work-group sizes, small batches
  and every DETP variant give the same irradiance; the run's seed and
  ``gather_seed`` change the rays.
- Every light: in a furnace (walls that emit and reflect) the gathered
  estimate is the series pi Le sum rho^k to max_depth bounces at every
  max_depth, and the plain exact one to max_depth - 1 (no emission
  counted twice, none lost); an area light seen only through a mirror
  reaches the point by its gather rays (the quadrature of its image); the
  Cornell box (an area light) gathers to its photons' mean.
- Refused with one error line: direct = "photons", bad values, camera
  sessions, methods other than DETP (sessions over given points:
  tests/test_gather_session.py; light sessions: tests/test_light_session.py).
"""

import numpy as np
import pyopencl as cl
import pytest

import oclgi
from analytic_scenes import H, INTENSITY, on_plane, plane_scene, quad
from oclgi.errors import OclgiError
from oclgi.estimators.detp_disc_index import DetpDiscIndex
from oclgi.study import Config, run_study

VARIANTS = ["detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache"]
RHO = 0.5
HALF = 3.0  # the plane is [-3, 3]^2 at y = 0, the light at height H over its centre


def _gathered_exact(px, pz, h, n=1200):
    """E at (px, h, pz) facing down: rho / pi * integral of E_plane(p) cos_x cos_p / r^2 dA (midpoint rule)."""
    xs = (np.arange(n) + 0.5) / n * 2 * HALF - HALF
    x, z = np.meshgrid(xs, xs, indexing="ij")
    e_plane = INTENSITY * H / (x**2 + z**2 + H**2) ** 1.5
    d2 = (x - px) ** 2 + (z - pz) ** 2 + h * h
    return float((RHO / np.pi * e_plane * h * h / d2**2).sum() * (2 * HALF / n) ** 2)


@pytest.fixture(scope="module")
def plane():
    return oclgi.Engine(plane_scene(8, HALF, albedo=RHO))


def test_point_light_over_a_plane(plane):
    xz = [[0.0, 0.0], [1.0, 0.5], [-1.5, 2.0]]
    h = 0.4
    got = plane.irradiance(on_plane(xz, h, -1), method="detp_disc_index", photons=20_000, direct="exact", gather=4096)
    want = np.array([_gathered_exact(x, z, h) for x, z in xz])
    assert want.min() > 0.02
    np.testing.assert_allclose(got.irradiance[:, 0], want, rtol=5e-3)
    # without gathering the same points read their own discs: no direct light, and the
    # plane's reflected light that crosses them (a different, noisy estimate)
    plain = plane.irradiance(on_plane(xz, h, -1), method="detp_disc_index", photons=20_000, direct="exact")
    assert not np.allclose(plain.irradiance[:, 0], got.irradiance[:, 0], rtol=5e-3)


def _shadow_engine():
    """A sun over a ground (albedo 0.5) and a grey 1 m roof 0.5 above it: under
    the roof the ground gets the light the roof's underside reflects back."""
    return oclgi.Engine(oclgi.load_dict({"mesh": [quad(0.0, 3.0, 0.5), quad(0.5, 0.5, 0.7)],
                                         "sun": {"direction": [0.3, -1.0, 0.1], "irradiance": [2.0, 1.5, 1.0]},
                                         "photons": {"count": 20_000, "seed": 4, "max_depth": 5}}))


@pytest.fixture(scope="module")
def shadow():
    engine = _shadow_engine()
    xz = np.random.default_rng(5).uniform(-1.5, 1.5, (24, 2))
    under = on_plane(xz, 1e-4)
    under[:8, 1], under[:8, 4] = 0.5 - 1e-4, -1.0  # the roof's underside
    return engine, under


def test_resolve_equals_a_float64_reference(shadow):
    engine, pts = shadow
    n_rays = 64
    run = engine.run(pts, method="detp_disc_index", photons=30_000, radius=0.15, direct="exact", gather=n_rays)
    est = run.complete(progress=False)
    g = est.estimator
    scale = est.scale
    hit_irr = np.empty((len(g.hits), 4), np.float32)
    cl.enqueue_copy(engine.queue, hit_irr, g.inner.resolve(scale))
    hit = g.hit_weights[:, 0] > 0  # the rays that met a surface (the rest left the scene)
    assert hit.mean() > 0.3 and (hit_irr[hit, 0] > 0).mean() > 0.5 and g.inner.accumulators().any()
    direct = cl.Buffer(engine.ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR,
                       hostbuf=np.zeros((len(pts), 4), np.float32))
    g.direct.add(g.positions, g.normals, len(pts), direct)
    d = np.empty((len(pts), 4), np.float32)
    cl.enqueue_copy(engine.queue, d, direct)
    w = g.hit_weights[:, :3].astype(np.float64).reshape(len(pts), n_rays, 3)
    e = hit_irr[:, :3].astype(np.float64).reshape(len(pts), n_rays, 3)
    np.testing.assert_allclose(est.irradiance, (d[:, :3] + (w * e).mean(axis=1)), rtol=2e-6, atol=1e-9)
    # the weights are the albedo seen (the roof 0.7, the ground 0.5) or 0 (a ray that left)
    assert set(np.unique(g.hit_weights[:, 0]).tolist()) <= set(np.float32([0.0, 0.5, 0.7]).tolist())
    assert np.all(np.abs(g.hits.xyz[hit, 1] - np.where(g.hit_weights[hit, 0] > 0.6, 0.5, 0.0)) < 1e-5)


def test_bit_for_bit(shadow):
    engine, pts = shadow
    kw = dict(photons=20_000, radius=0.15, direct="exact", gather=32, seed=3)
    first = engine.irradiance(pts, method="detp_disc_index", **kw).irradiance
    assert np.array_equal(engine.irradiance(pts, method="detp_disc_index", **kw).irradiance, first)
    for method in VARIANTS:
        assert np.array_equal(engine.irradiance(pts, method=method, **kw).irradiance, first), method
    other = oclgi.Engine(engine.scene, local_size=7, batch_bytes=16 * 48 * 1000)  # 1,000 paths per batch
    assert np.array_equal(other.irradiance(pts, method="detp_disc_index", **kw).irradiance, first)
    for change in ({"seed": 4}, {"gather_seed": 1}):
        again = engine.irradiance(pts, method="detp_disc_index", **{**kw, **change}).irradiance
        assert not np.array_equal(again, first), change
        np.testing.assert_allclose(again.mean(), first.mean(), rtol=0.1)


def test_adaptive_radii_at_the_hits(shadow):
    engine, pts = shadow
    est = engine.irradiance(pts, method="detp_disc_index", photons=20_000, direct="exact", gather=16,
                            radius_mode="adaptive")
    assert len(est.estimator.radii) == 16 * len(pts)
    assert np.isfinite(est.irradiance).all() and (est.irradiance > 0).any()


def test_refused(shadow, cornell):
    engine, pts = shadow
    with pytest.raises(OclgiError, match="needs direct = 'exact'"):
        engine.irradiance(pts, photons=1000, gather=8)
    for bad in (-1, 1.5, True, 70_000, "8", float("nan")):
        with pytest.raises(OclgiError, match="gather must be an integer"):
            engine.irradiance(pts, photons=1000, direct="exact", gather=bad)
    with pytest.raises(OclgiError, match="gather_seed must be"):
        engine.irradiance(pts, photons=1000, direct="exact", gather=8, gather_seed=-2)
    with pytest.raises(OclgiError, match="takes no option"):
        engine.irradiance(pts, method="photon_map", photons=1000, gather=8)
    points = oclgi.query_points(pts[:, :3], pts[:, 3:])
    with pytest.raises(OclgiError, match="Engine.estimator"):
        DetpDiscIndex(engine.queue, engine.compiled, points, 0.1, gather=8)


@pytest.fixture(scope="module")
def furnace():
    from analytic_scenes import box

    return oclgi.Engine(box(rho=0.5, le=1.0))


@pytest.mark.parametrize("max_depth", [1, 2, 4])
def test_the_furnace_series_at_every_bounce_count(furnace, max_depth):
    """Walls of albedo 1/2 emitting Le = 1: pi Le sum_{k < K} rho^k, K =
    max_depth without gathering (direct light by photons or exact), K =
    max_depth + 1 with (the hits' discs hold max_depth - 1 bounces, and
    one more is the gather's). Within 2% (the discs at hits near the
    box's edges read a little low)."""
    from analytic_scenes import face_points

    p, n = face_points(np.random.default_rng(0))
    pts = np.hstack([p, n])
    kw = dict(method="detp_disc_index", radius=0.08, photons=200_000, max_depth=max_depth)
    series = [np.pi * sum(RHO**k for k in range(K)) for K in (max_depth, max_depth + 1)]
    for options, expected in (({}, series[0]), ({"direct": "exact"}, series[0]),
                              ({"direct": "exact", "gather": 16}, series[1])):
        got = furnace.irradiance(pts, **kw, **options).irradiance[:, 0].astype(np.float64)
        assert abs(got.mean() / expected - 1) < 0.02, options


def test_an_area_light_seen_in_a_mirror():
    """A point facing down over a mirror floor (reflectance R), under a
    square light facing down that it cannot see: all its light comes
    through the mirror, from the light's image, by the gather rays alone
    (its direct light is 0, the rays meet no diffuse surface): R times
    the quadrature of the image."""
    R, y_light, half, h = 0.8, 1.0, 0.5, 0.5
    mirror = {"vertices": [[-6, 0, -6], [6, 0, -6], [6, 0, 6], [-6, 0, 6]], "faces": [[0, 2, 1], [0, 3, 2]],
              "material": {"kind": "mirror", "specular": [R] * 3}}
    light = {"vertices": [[-half, y_light, -half], [half, y_light, -half], [half, y_light, half],
                          [-half, y_light, half]], "faces": [[0, 1, 2], [0, 2, 3]], "albedo": [0.0] * 3,
             "emission": [2.0] * 3}
    engine = oclgi.Engine(oclgi.load_dict({"mesh": [mirror, light],
                                           "photons": {"count": 1000, "seed": 1, "max_depth": 3}}))
    xz = np.array([[0.0, 0.0], [0.4, -0.2], [1.2, 0.5]])
    pts = on_plane(xz, h, -1)
    got = engine.irradiance(pts, photons=2000, radius=0.1, direct="exact", gather=4096).irradiance[:, 0]
    n = 400  # the image: the square at y = -y_light, facing up, seen from (px, h, pz) facing down
    c = (np.arange(n) + 0.5) / n * 2 * half - half
    gx, gz = np.meshgrid(c, c, indexing="ij")
    expected = []
    for px, pz in xz:
        d2 = (gx - px) ** 2 + (gz - pz) ** 2 + (h + y_light) ** 2
        expected.append(R * 2.0 * ((h + y_light) ** 2 / d2**2).sum() * (2 * half / n) ** 2)
    expected = np.array(expected)
    assert np.abs(got / expected - 1).max() < 0.03


def test_the_cornell_box_gathers_to_its_photons(cornell):
    rng = np.random.default_rng(3)
    n = 200
    pts = np.column_stack([rng.uniform(-0.9, 0.9, n), np.full(n, 1e-4), rng.uniform(-0.9, 0.9, n),
                           np.zeros(n), np.ones(n), np.zeros(n)])
    kw = dict(method="detp_disc_index", photons=300_000, radius=0.1)
    photons = cornell.irradiance(pts, **kw).irradiance[:, 0].astype(np.float64)
    gathered = cornell.irradiance(pts, direct="exact", gather=32, **kw).irradiance[:, 0].astype(np.float64)
    assert abs(gathered.mean() / photons.mean() - 1) < 0.02


def test_the_study_compares_it(shadow):
    """`oclgi study` (run_study) takes the option like any other: its rows
    are labelled with it, and the seeds give the rays their noise."""
    engine, pts = shadow
    plain = Config("detp_disc_index", [4_000, 12_000], radius=0.15, direct="exact")
    gathered = Config("detp_disc_index", [4_000, 12_000], radius=0.15, direct="exact", gather=64)
    result = run_study(engine, [plain, gathered], points=pts, seeds=3, reference="detp:48000", progress=False)
    rows = [r for r in result.rows if "gather=64" in r.label]
    assert len(rows) == 2 and len(result.rows) == 4
    assert all(np.isfinite(r.summary["nrmse"]) for r in result.rows)
    assert all((r.variance > 0).any() for r in rows), "each seed has its own rays"


def test_a_render_gathers(scenes_dir):
    """An image takes the option too (the camera's visible points gather; a
    pixel that sees nothing gathers nothing): the same mean radiance as
    without gathering, to the noise of a small run."""
    engine = oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_ies.toml"))
    kw = dict(width=24, height=24, photons=100_000, method="detp_disc_index", direct="exact")
    gathered = engine.render(gather=32, **kw)
    plain = engine.render(**kw)
    assert np.isfinite(gathered.radiance).all()
    np.testing.assert_allclose(gathered.radiance.mean(), plain.radiance.mean(), rtol=0.1)
    assert not np.array_equal(gathered.radiance, plain.radiance)


def test_memory_is_checked_before_gathering(shadow):
    """N gather hits per point are N discs per point: a job whose hits
    cannot fit is refused before any work, naming the gather rays, where
    the same job without gathering is only checked for its points."""
    engine, pts = shadow
    many = np.tile(pts, (5000, 1))  # 120,000 points x 65,536 rays: 7.9e9 discs
    with pytest.raises(OclgiError, match="with 65,536 gather rays each.*use fewer gather rays"):
        engine.irradiance(many, photons=1000, direct="exact", gather=65536)
    with pytest.raises(OclgiError, match="with 65,536 gather rays a pixel.*use fewer gather rays"):
        engine.render(oclgi.Camera((0.0, 1.0, 4.0), (0.0, 0.0, 0.0)), width=640, height=480, photons=1000,
                      direct="exact", gather=65536)
