"""Exact direct light for DETP (``direct = "exact"``, oclgi/estimators/detp_direct.py).

- Point light over a plane (tests/analytic_scenes.py): the estimate is the
  closed form to float rounding, at any photon count and radius (no disc
  mean: the plane cannot light itself, so there is no indirect light).
- A sharp shadow crossing the disc, the foliage's failure
  (bench/complex_accuracy.py): a sun over a plane and a black square above
  it. A point in the shadow, near its edge, reads the sunlit part of its
  disc with fixed and with adaptive radii (over 20% of the sun); with the
  exact direct light it reads its shadow (0) and lit points read the sun.
- Every DETP variant gives the same sums (those of count_emitted = false)
  and the same irradiance; the work-group size changes nothing.
- A session recomputes the direct light at its pose: after moves of an
  occluder it equals a fresh session at the final pose, bit for bit.
- Area lights, a uniform sky and an environment map (sampled, with
  multiple importance sampling): a square light over a black plane, a sky
  over it and a map of one bright texel equal a float64 quadrature (or
  the closed form) within their noise, in each of the four MIS modes (each
  strategy alone and both combinations are unbiased only if the two
  strategies' densities agree, i.e. if the weights sum to 1); the same
  light cut into 20,000 triangles gives the same light; the value of a
  point depends on the point and the seed alone (not its index, the other
  points or the work-group size).
- Bad values and count_emitted = false give one error line.
"""

import numpy as np
import pytest

import oclgi
from analytic_scenes import exact, on_plane, plane_scene, quad
from test_instances import _rigid

VARIANTS = ["detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache"]
SUN = 2.0  # W/m^2 on a plane perpendicular to the sun
RADIUS = 0.2


def _shadow_scene(movable=False):
    """A 6 m ground (albedo 0.5) under a sun shining straight down, and a
    black 1 m square 0.5 m above it: the ground reads SUN outside the
    square's shadow and 0 in it (its reflected light leaves or is absorbed
    by the square's underside), exactly."""
    return oclgi.load_dict({"mesh": [quad(0.0, 3.0, name="ground", movable=False),
                                     quad(0.5, 0.5, 0.0, name="roof", movable=movable)],
                            "sun": {"direction": [0.0, -1.0, 0.0], "irradiance": [SUN] * 3},
                            "photons": {"count": 200_000, "seed": 4, "max_depth": 4}})


def _ground_points(xz):
    return on_plane(xz, 1e-6)


@pytest.fixture(scope="module")
def shadow():
    engine = oclgi.Engine(_shadow_scene())
    # in the shadow 0.3 r inside its edge; deep in the shadow; lit, far from it
    return engine, _ground_points([[0.5 - 0.3 * RADIUS, 0.0], [0.0, 0.1], [2.0, -1.5]])


def test_point_light_over_a_plane_is_the_closed_form():
    engine = oclgi.Engine(plane_scene(8, 3.0, albedo=0.5))
    rng = np.random.default_rng(3)
    xz = rng.uniform(-2.5, 2.5, (64, 2))
    pts = _ground_points(xz)
    for photons, radius in ((1_000, 0.5), (50_000, 0.05)):
        got = engine.irradiance(pts, method="detp_disc_index", photons=photons, radius=radius, direct="exact")
        assert not got.accumulators.any(), "a plane cannot light itself: no indirect light"
        np.testing.assert_allclose(got.irradiance[:, :3], np.repeat(exact(xz[:, 0], xz[:, 1])[:, None], 3, 1),
                                   rtol=2e-6)


@pytest.mark.parametrize("options", [{}, {"radius_mode": "adaptive"}], ids=["fixed", "adaptive"])
def test_a_shadow_edge_inside_the_disc(shadow, options):
    engine, pts = shadow
    kw = dict(method="detp_disc_index", photons=400_000, radius=RADIUS, **options)
    photons = engine.irradiance(pts, **kw).irradiance[:, 0]
    exact_direct = engine.irradiance(pts, direct="exact", **kw).irradiance[:, 0]
    # before: the point in the shadow reads the sunlit part of its disc
    assert photons[0] > 0.2 * SUN
    # after: the shadow reads 0, the lit ground the sun, exactly
    assert exact_direct[0] == 0.0 and exact_direct[1] == 0.0 and abs(exact_direct[2] / SUN - 1) < 1e-6


def test_every_variant_the_same(shadow):
    engine, pts = shadow
    rng = np.random.default_rng(8)
    under = _ground_points(rng.uniform(-0.45, 0.45, (40, 2)))  # the roof's underside: the ground's light
    under[:, 1], under[:, 4] = 0.5 - 1e-6, -1.0
    pts = np.concatenate([pts, _ground_points(rng.uniform(-2.8, 2.8, (200, 2))), under])
    kw = dict(photons=100_000, radius=RADIUS)
    runs = [engine.irradiance(pts, method=m, direct="exact", **kw) for m in VARIANTS]
    indirect = engine.irradiance(pts, method="detp", count_emitted=False, **kw)
    assert runs[0].accumulators.any()
    for r in runs:
        assert np.array_equal(r.accumulators, indirect.accumulators)
        assert np.array_equal(r.irradiance, runs[0].irradiance)
    other = oclgi.Engine(engine.scene, local_size=7)
    again = other.irradiance(pts, method="detp_disc_index", direct="exact", **kw)
    assert np.array_equal(again.irradiance, runs[1].irradiance)
    assert (runs[0].irradiance[:, 0] > indirect.irradiance[:, 0]).any()


@pytest.mark.parametrize("method", ["detp_disc_index", "detp"])
def test_session_recomputes_the_direct_light_at_its_pose(method):
    engine = oclgi.Engine(_shadow_scene(movable=True))
    rng = np.random.default_rng(12)
    pts = oclgi.query_points(np.column_stack([rng.uniform(-2, 2, 150), np.full(150, 1e-6), rng.uniform(-2, 2, 150)]),
                             np.tile([0.0, 1.0, 0.0], (150, 1)))
    kw = dict(method=method, radius=RADIUS, photons=20_000, direct="exact")
    s = oclgi.Session(engine, pts, **kw)
    first = s.irradiance().copy()
    for _ in range(4):
        s.move("roof", _rigid(rng, shift=1.5))
    fresh = oclgi.Session(s.engine, pts, **kw)
    assert np.array_equal(s.accumulators(), fresh.accumulators())
    assert np.array_equal(s.irradiance(), fresh.irradiance())
    assert not np.array_equal(s.irradiance(), first), "the shadow moved"
    s.move("roof", np.eye(4))
    assert np.array_equal(s.irradiance(), first)


def test_bad_input(shadow, cornell):
    engine, pts = shadow
    with pytest.raises(oclgi.OclgiError, match="direct must be one of 'photons', 'exact'"):
        engine.irradiance(pts, photons=1000, direct="shadow rays")
    with pytest.raises(oclgi.OclgiError, match="count_emitted = false leaves out"):
        engine.irradiance(pts, photons=1000, direct="exact", count_emitted=False)
    with pytest.raises(oclgi.OclgiError, match="takes no option"):
        engine.irradiance(pts, method="photon_map", photons=1000, direct="exact")
    for key, value, match in (("direct_samples", 0, "direct_samples must be an integer from 1"),
                              ("direct_samples", 2.5, "direct_samples must be an integer from 1"),
                              ("direct_mis", "heuristic", "direct_mis must be one of 'power', 'balance'")):
        with pytest.raises(oclgi.OclgiError, match=match):
            cornell.irradiance(pts, photons=1000, direct="exact", **{key: value})


# -- lights that are not deltas: area lights, the sky, environment maps ----------

LE = 3.0  # the square light's radiance, W/m^2/sr
LIGHT_Y, LIGHT_HALF = 1.0, 0.5
MIS = ["power", "balance", "light", "bsdf"]


def _tilted(xz, angles):
    """Ground points at xz with normals tilted by ``angles`` about z."""
    pts = _ground_points(xz)
    pts[:, 3], pts[:, 4] = np.sin(angles), np.cos(angles)
    return pts


def _square_light_scene(cells=1):
    """A black 6 m ground under a square light of side 1 m, 1 m above it,
    facing down, cut into cells x cells squares: the ground reads the
    light's direct irradiance only (it reflects nothing)."""
    from analytic_scenes import grid

    v, f = grid(cells, LIGHT_HALF)
    v = v + [0.0, LIGHT_Y, 0.0]
    return oclgi.load_dict({"mesh": [quad(0.0, 3.0, albedo=0.0, name="ground"),
                                     {"vertices": v, "faces": f[:, ::-1], "albedo": [0.0] * 3,
                                      "emission": [LE] * 3, "name": "light"}],
                            "photons": {"count": 1000, "seed": 1, "max_depth": 2}})


def _square_quadrature(pts, n=400):
    """E = integral over the light of L cos_x cos_l / r^2 dA (midpoint rule, float64)."""
    c = (np.arange(n) + 0.5) / n * 2 * LIGHT_HALF - LIGHT_HALF
    gx, gz = np.meshgrid(c, c, indexing="ij")
    y = np.stack([gx.ravel(), np.full(gx.size, LIGHT_Y), gz.ravel()], 1)
    out = []
    for p in pts:
        d = y - p[:3]
        r2 = (d * d).sum(1)
        w = d / np.sqrt(r2)[:, None]
        cos_x = np.clip(w @ p[3:6], 0, None)
        out.append(LE * (cos_x * w[:, 1] / r2).sum() * (2 * LIGHT_HALF / n) ** 2)
    return np.array(out)


@pytest.fixture(scope="module")
def square():
    engine = oclgi.Engine(_square_light_scene())
    rng = np.random.default_rng(5)
    pts = _tilted(rng.uniform(-1.5, 1.5, (10, 2)), rng.uniform(-1.0, 1.0, 10))
    return engine, pts, _square_quadrature(pts)


# The error each mode stays within at 2,048 pairs of samples, relative to
# the point's value or a fifth of the largest (a point that sees the light
# edge-on has little): 5 times the spread measured over seeds (0.45-0.5%
# for light samples alone and both heuristics, 4% for cosine samples
# alone, few of which meet the light from points far from it).
SQUARE_TOLERANCE = {"power": 0.025, "balance": 0.025, "light": 0.025, "bsdf": 0.2}


def _relative(got, expected):
    return np.abs(got - expected) / np.maximum(expected, 0.2 * expected.max())


@pytest.mark.parametrize("mis", MIS)
def test_a_square_area_light_is_the_quadrature(square, mis):
    engine, pts, expected = square
    got = engine.irradiance(pts, photons=1000, radius=0.1, direct="exact", direct_mis=mis,
                            direct_samples=2048).irradiance[:, :3].astype(np.float64)
    assert not got.std(axis=1).any(), "a grey light lights every channel alike"
    assert _relative(got[:, 0], expected).max() < SQUARE_TOLERANCE[mis]


def test_the_direct_light_is_the_points_own(square):
    """Keyed by the point's bits and the run's seed: permuted points, a
    subset and another work-group size give the same bits; another seed
    other noise of the same mean."""
    engine, pts, expected = square
    kw = dict(photons=1000, radius=0.1, direct="exact", direct_samples=16)
    first = engine.irradiance(pts, **kw).irradiance
    order = np.random.default_rng(0).permutation(len(pts))
    assert np.array_equal(engine.irradiance(pts[order], **kw).irradiance, first[order])
    assert np.array_equal(engine.irradiance(pts[3:5], **kw).irradiance, first[3:5])
    other = oclgi.Engine(engine.scene, local_size=7)
    assert np.array_equal(other.irradiance(pts, **kw).irradiance, first)
    seeds = [engine.irradiance(pts, seed=s, **dict(kw, direct_samples=64)).irradiance[:, 0] for s in range(2, 10)]
    assert not np.array_equal(engine.irradiance(pts, seed=2, **kw).irradiance, first)
    assert _relative(np.mean(seeds, axis=0), expected).max() < 0.05


def test_a_light_of_20000_triangles_is_the_same_light(square):
    engine, pts, expected = square
    fine = oclgi.Engine(_square_light_scene(cells=100))
    assert fine.compiled.n_spread == 20_000
    got = fine.irradiance(pts, photons=1000, radius=0.1, direct="exact", direct_samples=2048).irradiance[:, 0]
    assert _relative(got, expected).max() < SQUARE_TOLERANCE["power"]


SKY = 0.7  # W/m^2/sr


@pytest.mark.parametrize("mis", MIS)
def test_a_sky_over_a_plane(mis):
    """A hemisphere sky over a black plane: a point whose normal is tilted
    by a from up reads pi L (1 + cos a) / 2 (the plane hides the rest)."""
    engine = oclgi.Engine(oclgi.load_dict({"mesh": [quad(0.0, 50.0, albedo=0.0)], "sky": {"radiance": [SKY] * 3},
                                           "photons": {"count": 1000, "seed": 1, "max_depth": 2}}))
    angles = np.array([0.0, 0.3, 0.8, 1.2, 1.5])
    pts = _tilted(np.zeros((5, 2)), angles)
    got = engine.irradiance(pts, photons=1000, radius=0.1, direct="exact", direct_mis=mis,
                            direct_samples=1024).irradiance[:, 0]
    expected = np.pi * SKY * (1 + np.cos(angles)) / 2
    assert np.abs(got / expected - 1).max() < 0.02


def test_an_environment_map_of_one_bright_texel(tmp_path):
    """A black map but one texel of radiance B: E = B times the integral of
    cos over the texel (float64 quadrature), for points facing several ways."""
    from test_lights import _write_exr

    H, W, i, j, B = 8, 16, 2, 5, 40.0
    rad = np.zeros((H, W, 3), np.float32)
    rad[i, j] = B
    _write_exr(tmp_path / "texel.exr", rad)
    engine = oclgi.Engine(oclgi.load_dict({"mesh": [quad(-20.0, 0.1, albedo=0.0)],
                                           "sky": {"map": str(tmp_path / "texel.exr")},
                                           "photons": {"count": 1000, "seed": 1, "max_depth": 2}}))
    normals = np.array([[0, 1, 0], [0.6, 0.8, 0], [-0.3, 0.5, 0.81], [1, 0, 0], [0, 0, -1]], float)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    pts = np.hstack([np.zeros((5, 3)), normals])
    m = 400  # quadrature: uniform in cos theta and phi over the texel
    ct = np.cos(np.pi * i / H) + (np.arange(m) + 0.5) / m * (np.cos(np.pi * (i + 1) / H) - np.cos(np.pi * i / H))
    phi = 2 * np.pi * (j + (np.arange(m) + 0.5) / m) / W
    cc, pp = np.meshgrid(ct, phi, indexing="ij")
    st = np.sqrt(1 - cc**2)
    w = np.stack([st * np.sin(pp), cc, -st * np.cos(pp)], -1).reshape(-1, 3)
    omega = 2 * np.pi / W * (np.cos(np.pi * i / H) - np.cos(np.pi * (i + 1) / H))
    expected = B * np.clip(w @ normals.T, 0, None).mean(0) * omega
    assert (expected[:4] > 0).all() and expected[4] == 0  # the last faces away from the texel
    for mis, tol in (("power", 0.01), ("light", 0.01), ("bsdf", 0.25)):
        got = engine.irradiance(pts, photons=1000, radius=0.1, direct="exact", direct_mis=mis,
                                direct_samples=4096).irradiance[:, 0]
        lit = expected > 0
        assert np.abs(got[lit] / expected[lit] - 1).max() < tol, mis
        assert not got[~lit].any()


def test_the_cornell_box_direct_light_matches_its_photons(cornell):
    """The area light's exact direct light plus the discs' indirect light
    equals the photons' direct and indirect light on average over the
    floor (the same light, told apart), on points whose discs lie wholly
    on open floor (0.12 from the walls and the boxes' footprints: a disc
    that reaches under a box or past a wall reads low, which the exact
    direct light does not). Measured 0.3-1.0% apart over seeds: the photons'
    noise, and the disc's mean under the light's peak, a little low."""
    scene = cornell.scene
    rng = np.random.default_rng(2)
    xz = rng.uniform(-0.85, 0.85, (2000, 2))
    keep = np.ones(len(xz), bool)
    for k, m in enumerate(scene.materials):
        if m.name.endswith("Box"):
            v = scene.vertices[scene.faces[scene.tri_material == k]].reshape(-1, 3)
            lo, hi = v[:, [0, 2]].min(0) - 0.12, v[:, [0, 2]].max(0) + 0.12
            keep &= ~((xz > lo) & (xz < hi)).all(axis=1)
    xz = xz[keep][:300]
    pts = _ground_points(xz)
    kw = dict(method="detp_disc_index", photons=1_000_000, radius=0.1)
    photons = cornell.irradiance(pts, **kw).irradiance[:, 0].astype(np.float64)
    exact_direct = cornell.irradiance(pts, direct="exact", **kw).irradiance[:, 0].astype(np.float64)
    assert len(xz) == 300 and abs(exact_direct.mean() / photons.mean() - 1) < 0.015


def test_an_extended_run_takes_the_longer_runs_default(cornell):
    """The default sample count grows with the photons: a run extended to
    more photons takes the total's (for the points and a gather's hits), so
    it equals one run of the total bit for bit."""
    from oclgi.estimators.detp_direct import default_samples

    engine = cornell
    pts = np.array([[0.0, 0.01, 0.0, 0.0, 1.0, 0.0], [-0.99, 1.0, 0.2, 1.0, 0.0, 0.0], [0.3, 1.0, -1.04, 0.0, 0.0, 1.0]])
    assert default_samples(20_000, len(pts)) != default_samples(60_000, len(pts))
    for extra in ({}, {"gather": 4}):
        kw = dict(method="detp_disc_index", radius=0.1, direct="exact", **extra)
        run = engine.run(pts, photons=20_000, **kw)
        run.extend(40_000)
        assert np.array_equal(run.complete(False).irradiance, engine.irradiance(pts, photons=60_000, **kw).irradiance)
