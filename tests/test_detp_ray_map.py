"""DETP with a ray map: identical to plain DETP.

On the Cornell box and the bunny scene, for the three radius fractions, with
and without the emitted segments, for several leaf sizes, with and without
cutting segments into pieces, for several work-group sizes and over several
batches, the fixed-point accumulators equal plain DETP's bit for bit
(DESIGN.md 3). Adversarial segments check that the culling is conservative
and that a segment cut into pieces is counted once.
"""


import pytest

import oclgi
from exactness import RADIUS_FRACTIONS, check_adversarial, check_camera_misses, check_replace_points
from oclgi.errors import OclgiError

METHOD = "detp_ray_map"  # the `same_as_plain` fixture's (conftest.py)


@pytest.mark.parametrize("count_emitted", [True, False])
@pytest.mark.parametrize("frac", RADIUS_FRACTIONS)
@pytest.mark.parametrize("scene", ["cornell", "bunny"])
def test_same_as_plain(same_as_plain, scene, frac, count_emitted):
    same_as_plain(scene, frac, count_emitted)


@pytest.mark.parametrize("piece", [0.0, 0.05])
@pytest.mark.parametrize("leaf_size", [1, 8, 32])
@pytest.mark.parametrize("scene", ["cornell", "bunny"])
def test_leaf_sizes_and_pieces(same_as_plain, points, scene, leaf_size, piece):
    est = same_as_plain(scene, RADIUS_FRACTIONS[1], leaf_size=leaf_size, piece=piece, count_work=True)
    assert est.work["u"] < est.stats.segments * len(points[scene]) / 2  # the map does cull


# 1 and 7 against the launches' own size (64 where they name none: every other test runs it); 64 itself in the full suite
@pytest.mark.parametrize("local_size", [1, 7, pytest.param(64, marks=pytest.mark.full)])
def test_work_group_sizes_and_batches(engines, same_as_plain, local_size):
    """Also split into batches of 3,000 paths: one ray map per batch."""
    e = oclgi.Engine(engines["cornell"].scene, local_size=local_size, batch_bytes=3000 * 16 * 48)
    same_as_plain("cornell", RADIUS_FRACTIONS[2], engine=e)


def test_camera_points_with_misses(engines):
    check_camera_misses(engines["cornell"], METHOD)


@pytest.mark.parametrize("count_emitted", [True, False])
def test_adversarial_segments(engines, count_emitted):
    # piece 0.004: many segments cut into many pieces (up to the cap), so
    # crossings land on piece edges and must be counted exactly once.
    check_adversarial(engines["cornell"], METHOD, 8, count_emitted,
                      [dict(leaf_size=n, piece=piece) for n, piece in ((1, 0.0), (32, 0.0), (8, 0.004), (32, 0.05))])


@pytest.mark.parametrize("bad", [{"leaf_size": 0}, {"leaf_size": 33}, {"leaf_size": 2.5}, {"piece": -1.0}])
def test_bad_options(engines, points, bad):
    with pytest.raises(OclgiError):
        engines["cornell"].irradiance(points["cornell"], method=METHOD, photons=100, **bad)


def test_replace_points(engines):
    check_replace_points(engines["cornell"], METHOD)
