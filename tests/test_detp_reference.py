"""Device DETP and Impact Count against the float64 numpy references, on the
same segments (the Cornell box), and photon tracing against its physics."""

import math

import numpy as np
import pytest

from reference import detp_reference


@pytest.mark.parametrize("radius,count_emitted", [(0.05, True), (0.2, True), (0.1, False)])
def test_detp_equals_float64_reference(cornell, radius, count_emitted):
    photons, depth = 20_000, 16
    segs, _ = cornell.trace(photons=photons, max_depth=depth)
    pts = cornell.camera_points(width=12, height=12)
    on = pts.tri >= 0
    est = cornell.irradiance(pts, method="detp", photons=photons, max_depth=depth, radius=radius,
                             count_emitted=count_emitted)
    ext = 10.0 * cornell.compiled.eps
    ref = detp_reference(pts.xyz[on], pts.normals[on, :3], segs, radius, ext, count_emitted, depth)
    got = est.accumulators[on] / est.scale
    # float32 geometry vs float64: a segment right on a disc's rim may go
    # either way; its power is ~1/photons of the total, so allow one.
    one = segs["power"].max()
    assert np.abs(got - ref).max() <= one * 1.01 and np.abs(got - ref).sum() <= 0.002 * ref.sum()
    assert ref.sum() > 0


def test_trace_energy_and_layout(cornell):
    """Emitted power equals the light's power; the store is path-major with
    zeroed slots past each path's end; Russian roulette keeps power bounded."""
    photons, depth = 50_000, 8
    segs, lens = cornell.trace(photons=photons, max_depth=depth)
    seg = segs.reshape(photons, depth)
    first = seg[:, 0]
    emitted = first["power"].astype(np.float64).sum(axis=0)
    np.testing.assert_allclose(emitted, cornell.compiled.total_power, rtol=1e-4)
    # light: Ke (17, 12, 4) over a 0.47 x 0.38 quad, pi * A * Le
    np.testing.assert_allclose(cornell.compiled.total_power, math.pi * 0.47 * 0.38 * np.array([17, 12, 4]), rtol=1e-5)
    used = np.arange(depth)[None, :] < lens[:, None]
    assert (np.linalg.norm(seg["dir"], axis=2)[used] > 0.999).all()
    assert (seg["power"][~used] == 0).all() and (seg["dir"][~used] == 0).all()
    assert (seg["path"] == np.arange(photons)[:, None]).all()
    # each segment starts where the previous one ended
    prev_end = seg["org"][:, :-1] + seg["t_end"][:, :-1, None] * seg["dir"][:, :-1]
    cont = used[:, 1:]
    assert np.abs(seg["org"][:, 1:][cont] - prev_end[cont]).max() < 1e-3
    assert seg["power"].max() <= first["power"].max() * (1 + 1e-6)
    # the box is closed but for its front: most segments hit something
    assert (seg["tri"][used] >= 0).mean() > 0.8


def test_reflected_power_follows_albedo(cornell):
    """Expected power of bounce b+1 = albedo of the hit x power of bounce b
    (Russian roulette is unbiased): checked on the summed power per bounce."""
    photons, depth = 200_000, 4
    segs, _ = cornell.trace(photons=photons, max_depth=depth)
    seg = segs.reshape(photons, depth)
    albedo = np.array([m.albedo for m in cornell.scene.materials])[cornell.scene.tri_material]
    for b in range(2):
        s = seg[:, b]
        hit = s["tri"] >= 0
        expected = (s["power"][hit] * albedo[s["tri"][hit]]).astype(np.float64).sum(axis=0)
        np.testing.assert_allclose(seg[:, b + 1]["power"].astype(np.float64).sum(axis=0), expected, rtol=0.02)
