"""Defaults that are fast: the method when none is given is DETP with disc
indexing (plain DETP, the oracle, gives the same sums far slower), and a
disc too small for the photons is said, with the numbers."""

import tomllib
import warnings

import pytest
from small_scene import MOVING_BLOCK

import oclgi
from oclgi.params import RunParams
from oclgi.scene.scene import OclgiWarning


def test_default_method_is_the_disc_index():
    assert RunParams().method == "detp_disc_index"
    scene = oclgi.load_dict(tomllib.loads(MOVING_BLOCK))  # no [estimator] table
    assert scene.settings.method == "detp_disc_index"
    engine = oclgi.Engine(scene)
    pts = engine.camera_points()
    est = engine.irradiance(pts, photons=20_000)
    assert est.stats.method == "detp_disc_index" and type(est.estimator).__name__ == "DetpDiscIndex"
    # the oracle's sums, bit for bit
    assert est.accumulators.tobytes() == engine.irradiance(pts, method="detp", photons=20_000).accumulators.tobytes()


def test_a_radius_too_small_for_the_photons_warns(cornell):
    pts = cornell.camera_points(width=8, height=8)
    with pytest.warns(OclgiWarning, match=r"radius 0\.002: each disc catches about 0\.\d+ segments .* more photons"):
        cornell.irradiance(pts, photons=20_000, radius=0.002)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the scene's own radius at its own photon count: no warning
        cornell.irradiance(pts)
