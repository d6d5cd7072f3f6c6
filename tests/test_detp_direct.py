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
- Bad values, scenes with area lights and count_emitted = false give one
  error line.
"""

import numpy as np
import pytest

import oclgi
from analytic_scenes import exact, plane_scene, quad
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
    xz = np.asarray(xz, float)
    return np.column_stack([xz[:, 0], np.full(len(xz), 1e-6), xz[:, 1], np.zeros(len(xz)), np.ones(len(xz)),
                            np.zeros(len(xz))])


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
    with pytest.raises(oclgi.OclgiError, match="delta lights only"):
        cornell.irradiance(pts, photons=1000, direct="exact")
