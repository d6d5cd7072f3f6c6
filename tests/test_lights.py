"""The light kinds (oclgi/scene/lights.py, kernels/light.h) against closed forms.

Each scene is a black plane y = 0 (nothing reflects) under one light,
direct light only (max_depth 1), measured with the plain ``detp`` oracle
and with the default estimator (detp_disc_index), which must agree bit for
bit with it; the expected value is the closed form averaged over the disc
(DETP's estimate is the mean irradiance over its disc):

* spot light at height h, axis down: E = I s(cos theta) cos theta / r^2,
  s pbrt-v4's smoothstep profile, and 0 outside the cone;
* sun at angle alpha from the zenith: E cos alpha, and exactly 0 in the
  shadow of an occluder;
* uniform sky of radiance L, over the upper hemisphere or the whole sphere:
  pi L on the plane's upper side;
* point light: I cos theta / r^2, as in test_analytic.py.

Tolerances: 10^6 photons; a disc of radius d on the plane catches about
10^6 x (share of the photons reaching it) segments, and the bounds below
are about four standard errors of that count (stated per test).
"""

import base64
import json
import math
import shutil
import struct
import warnings

import numpy as np
import OpenImageIO as oiio
import pyopencl as cl
import pytest
from analytic_scenes import disc_mean, on_plane, square

import oclgi
from oclgi.cl.layout import Emitter
from oclgi.cl.programs import ProgramCache
from oclgi.errors import OclgiError
from oclgi.scene import lights
from oclgi.scene.scene import OclgiWarning, PointLight
from oclgi.study import mitsuba as mitsuba_reference

H = 1.0
UP = (0.0, 1.0, 0.0)


def _scene(light_tables, half=1.0, extra_meshes=(), photons=1_000_000, seed=3, max_depth=1):
    v, f = square(half)
    meshes = [{"vertices": v, "faces": f, "albedo": [0, 0, 0]}, *extra_meshes]
    return oclgi.load_dict({"mesh": meshes, **light_tables,
                            "photons": {"count": photons, "seed": seed, "max_depth": max_depth}})


def _both(engine, pts, radius):
    """DETP's and the default estimator's irradiance (channel 0); they are the same sums."""
    plain = engine.irradiance(pts, method="detp", radius=radius)
    default = engine.irradiance(pts, radius=radius)
    assert default.stats.method != "detp" and np.array_equal(plain.accumulators, default.accumulators)
    return plain.irradiance[:, 0].astype(np.float64)


# -- spot -------------------------------------------------------------------------------------------------------

SPOT = {"position": [0, H, 0], "direction": [0, -1, 0], "intensity": [2.0, 1.0, 0.5], "cone_angle": 30, "cone_delta": 10}


@pytest.fixture(scope="module")
def spot():
    return oclgi.Engine(_scene({"spot_light": [SPOT]}, half=1.0))


def test_spot_light_power_is_exact_for_its_profile(spot):
    """Phi = 2 pi I ((1 - cos start) + (cos start - cos end) / 2), and the
    profile's integral over the sphere, by quadrature, is that factor."""
    light = spot.scene.lights[0]
    cs, ce = math.cos(math.radians(20)), math.cos(math.radians(30))
    factor = 2 * math.pi * ((1 - cs) + (cs - ce) / 2)
    np.testing.assert_allclose(spot.compiled.total_power, factor * np.array([2.0, 1.0, 0.5]), rtol=1e-12)
    c = np.linspace(-1, 1, 2_000_001)
    integral = 2 * math.pi * np.trapezoid(light.profile(c), c)
    assert abs(integral / factor - 1) < 1e-6


def test_spot_light_plane(spot):
    """Inside the full-intensity cone (theta < 20 deg) E = I cos^3 theta / h^2, in the
    smoothstep band (20..30 deg) the profile falls to 0, and past the cone
    nothing arrives. Disc radius 0.06: some 10^4 segments a disc near the
    axis (1% noise), fewer in the band: within 4% (the band's values are
    smaller and steeper), and their mean within 1.5%."""
    light = spot.scene.lights[0]

    def exact(x, z):
        r = np.sqrt(x * x + z * z + H * H)
        cos = H / r
        return 2.0 * light.profile(cos) * cos / r**2

    xs = np.array([0.0, 0.1, 0.2, 0.28, 0.42, 0.48])
    pts = [(x, 0.0) for x in xs] + [(0.0, x) for x in xs[1:]] + [(0.75, 0.0), (0.0, -0.8)]
    e = _both(spot, on_plane(pts), 0.06)
    ref = np.array([disc_mean(x, z, 0.06, 160, exact) for x, z in pts])
    inside = ref > 0
    assert inside.sum() == len(pts) - 2 and np.abs(e[inside] / ref[inside] - 1).max() < 0.04
    assert abs(np.mean(e[inside] / ref[inside]) - 1) < 0.015
    assert np.all(e[~inside] == 0)  # outside the cone: no photon at all


def test_spot_light_photons_stay_under_phi_max(spot):
    """Photons leave uniformly over the cone and carry the profile: the
    record's power is the cone's largest, so none exceeds 1 (phi_max)."""
    s, _ = spot.trace(photons=50_000)
    units = s["power"] / spot.photon_watts(50_000)
    assert units.max() <= 1.0 + 1e-6 and units.min() >= 0.0
    assert (units[:, 0] < 0.5).mean() > 0.05  # the falloff band's photons carry less


# -- sun --------------------------------------------------------------------------------------------------------

ALPHA = math.radians(30)
SUN_DIR = [math.sin(ALPHA), -math.cos(ALPHA), 0.0]


def test_sun_plane_and_shadow():
    """E cos alpha on the open plane (radius 0.2: some 2 10^4 segments a
    disc, 0.7% noise: within 3%, mean within 1%); in the shadow of a black
    square 0.5 above the plane (shifted 0.5 tan alpha along x) exactly 0."""
    occ_v, occ_f = square(0.2, y=0.5)
    occluder = {"vertices": occ_v, "faces": occ_f[:, ::-1], "albedo": [0, 0, 0]}  # facing down, at the sun's photons
    eng = oclgi.Engine(_scene({"sun": [{"direction": SUN_DIR, "irradiance": [2.0, 2.0, 2.0]}]},
                              extra_meshes=[occluder]))
    lit = [(-0.6, 0.0), (-0.5, 0.5), (0.6, -0.6), (0.0, 0.6), (-0.6, -0.6)]
    e = _both(eng, on_plane(lit), 0.2)
    assert np.abs(e / (2.0 * math.cos(ALPHA)) - 1).max() < 0.03
    assert abs(np.mean(e) / (2.0 * math.cos(ALPHA)) - 1) < 0.01
    shift = 0.5 * math.tan(ALPHA)
    shadow = [(shift, 0.0), (shift + 0.1, 0.1), (shift - 0.1, -0.1)]
    assert np.all(_both(eng, on_plane(shadow), 0.05) == 0)


def test_sun_power_covers_the_bounding_sphere():
    eng = oclgi.Engine(_scene({"sun": [{"direction": [0, -1, 0], "irradiance": [1, 2, 3]}]}, photons=1000))
    c, r = lights.bounding_sphere(eng.scene)
    np.testing.assert_allclose(eng.compiled.total_power, math.pi * r * r * np.array([1, 2, 3]), rtol=1e-12)
    s, _ = eng.trace(photons=20_000)
    o = s["org"].astype(np.float64)
    assert (np.linalg.norm(o - c, axis=1) >= r * (1 - 1e-5)).all()  # every photon starts outside the sphere
    assert np.allclose(s["dir"], [0, -1, 0])


# -- sky --------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("hemisphere", [True, False])
def test_uniform_sky_plane(hemisphere):
    """pi L on the plane's upper side, whether the sky covers the upper
    hemisphere or the whole sphere (the plane's lower side takes the rest).
    Radius 0.2: about 10^4 segments a disc, 1% noise: within 4%, mean within 1.5%."""
    eng = oclgi.Engine(_scene({"sky": {"radiance": [1.0, 0.5, 0.25], "hemisphere": hemisphere}}))
    e = _both(eng, on_plane([(0.0, 0.0), (0.5, 0.0), (-0.5, 0.3), (0.3, -0.6), (-0.6, -0.6), (0.6, 0.6)]), 0.2)
    assert np.abs(e / math.pi - 1).max() < 0.04 and abs(np.mean(e) / math.pi - 1) < 0.015
    _, r = lights.bounding_sphere(eng.scene)
    omega = 2 * math.pi if hemisphere else 4 * math.pi
    np.testing.assert_allclose(eng.compiled.total_power, math.pi * r * r * omega * np.array([1, 0.5, 0.25]), rtol=1e-12)
    s, _ = eng.trace(photons=20_000)
    down = s["dir"][:, 1] <= 0
    assert down.all() if hemisphere else 0.45 < down.mean() < 0.55


def test_every_detp_variant_sums_the_same_under_sun_and_sky():
    """Photons that start outside the scene's bounding sphere (sun, sky) go
    through the accelerated DETP variants' segment structures as well: each
    gives the plain oracle's sums bit for bit."""
    occ_v, occ_f = square(0.3, y=0.4)
    sc = _scene({"sun": [{"direction": SUN_DIR, "irradiance": [1, 1, 1]}], "sky": {"radiance": [0.2, 0.2, 0.2]}},
                extra_meshes=[{"vertices": occ_v, "faces": occ_f, "albedo": [0.5, 0.5, 0.5]}], photons=50_000,
                max_depth=4)
    eng = oclgi.Engine(sc)
    pts = on_plane(np.random.default_rng(1).uniform(-0.9, 0.9, (64, 2)))
    ref = eng.irradiance(pts, method="detp", radius=0.1).accumulators
    for method in ("detp_disc_index", "detp_ray_map", "detp_sphere_cache"):
        assert np.array_equal(eng.irradiance(pts, method=method, radius=0.1).accumulators, ref), method


# -- point (as today) -------------------------------------------------------------------------------------------

def test_point_light_plane():
    """I cos theta / r^2 (test_analytic.py's scene, here through both estimators):
    radius 0.15, about 10^4 segments a disc near the axis: within 4%."""
    eng = oclgi.Engine(_scene({"point_light": [{"position": [0, H, 0], "intensity": [1, 1, 1]}]}, half=2.0))
    pts = [(0.0, 0.0), (0.3, 0.2), (-0.5, 0.4), (0.8, -0.6)]
    e = _both(eng, on_plane(pts), 0.15)
    ref = np.array([disc_mean(x, z, 0.15, 160, lambda x, z: H / (x * x + z * z + H * H) ** 1.5) for x, z in pts])
    assert np.abs(e / ref - 1).max() < 0.04


def test_point_light_class_is_where_it_was():
    assert PointLight is lights.PointLight is oclgi.PointLight
    assert oclgi.SpotLight is lights.SpotLight and oclgi.SunLight is lights.SunLight
    assert oclgi.SkyLight is lights.SkyLight


# -- every kind together: one CDF, phi_max ---------------------------------------------------------------------

def test_all_kinds_share_one_run_under_phi_max():
    """An area light, a point, a spot, a sun and a sky in one scene: each is
    chosen in proportion to its power (the segments leaving each kind are
    counted), and no photon carries more than phi_max."""
    lv, lf = square(0.1, y=0.8)
    area = {"vertices": lv, "faces": lf[:, ::-1], "albedo": [0, 0, 0], "emission": [3, 3, 3]}
    sc = _scene({"point_light": [{"position": [0.5, 0.5, 0], "intensity": [0.2, 0.2, 0.2]}],
                 "spot_light": [SPOT], "sun": [{"direction": SUN_DIR, "irradiance": [0.3, 0.3, 0.3]}],
                 "sky": {"radiance": [0.1, 0.1, 0.1]}}, extra_meshes=[area], photons=200_000)
    eng = oclgi.Engine(sc)
    rows = lights.emitter_rows(sc)
    assert list(rows.kind) == [0, 0, 1, 2, 3, 4]
    n = 200_000
    s, _ = eng.trace(photons=n)
    assert (s["power"] / eng.photon_watts(n)).max() <= 1 + 1e-6
    # each kind's photons carry its emitted power in total (the spot: its exact power, the profile included)
    o = s["org"].astype(np.float64)
    c, r = lights.bounding_sphere(sc)
    far = np.linalg.norm(o - c, axis=1) > r * 0.999
    from_point = np.all(np.isclose(o, [0.5, 0.5, 0]), axis=1)
    from_spot = np.all(np.isclose(o, [0, H, 0]), axis=1)
    from_area = np.isclose(o[:, 1], 0.8, atol=1e-3) & ~far
    watts = s["power"][:, 0].astype(np.float64)  # each photon's share of its emitter's watts
    expected = rows.power[:, 0]
    for mask, want in ((from_area, expected[:2].sum()), (from_point, expected[2]), (from_spot, expected[3]),
                       (far, expected[4] + expected[5])):
        assert abs(watts[mask].sum() / want - 1) < 0.05


# -- light_pdf_dir: the density of what light_sample_le emits ---------------------------------------------------

PDF_PROBE = """
#include "light.h"
__kernel void pdf_probe(__global const Emitter *em, __global const float *table, __global const float4 *r, int n,
                        __global float *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    LightSample s = light_sample_le(em, r[2 * i], r[2 * i + 1], 0.0f, table);
    out[8 * i + 0] = s.o.x; out[8 * i + 1] = s.o.y; out[8 * i + 2] = s.o.z;
    out[8 * i + 3] = s.d.x; out[8 * i + 4] = s.d.y; out[8 * i + 5] = s.d.z;
    out[8 * i + 6] = s.power.x;
    out[8 * i + 7] = light_pdf_dir(em, s.d, table);
}
"""


def light_samples(cl_env, emitter, table, seed, n=200_000):
    """n samples of light_sample_le from seeded uniforms for the emitter
    ``emitter`` ((kind, p, e1, e2, a, b), power 1, its tables at the start of
    ``table``): (n, 8) float32 rows of origin, direction, power and
    light_pdf_dir (PDF_PROBE)."""
    ctx, queue = cl_env
    probe = cl.Program(ctx, PDF_PROBE).build(options=ProgramCache(ctx).options(())).pdf_probe
    u = (np.floor(np.random.default_rng(seed).random((2 * n, 4)) * 2**24) / 2**24).astype(np.float32)
    em = np.zeros(1, Emitter)
    em["kind"], em["p"], em["e1"], em["e2"], em["a"], em["b"] = emitter
    em["power"] = 1.0
    em["tri"] = 0  # the environment map's tables start the table buffer
    mf = cl.mem_flags
    bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in (em, np.asarray(table, np.float32), u)]
    out_buf = cl.Buffer(ctx, mf.WRITE_ONLY, 8 * 4 * n)
    probe(queue, (n,), None, *bufs, np.int32(n), out_buf)
    out = np.empty((n, 8), np.float32)
    cl.enqueue_copy(queue, out, out_buf)
    return out


def test_light_pdf_dir_is_the_sampling_density(cl_env):
    """For samples of each kind, the mean of 1 / light_pdf_dir is the measure
    of what the kind samples over: 4 pi (point), the cone's solid angle
    (spot), area x 2 pi (triangle: position x hemisphere), pi R^2 (sun:
    position only, its direction a delta), pi R^2 x 4 pi or 2 pi (sky), and
    pi R^2 x 4 pi for an environment map with no black texel, which samples
    by luminance: there 1 / pdf varies from texel to texel.
    An unbiased estimate when the pdf is the density: 2 10^5 samples, within 1%."""
    e1, e2 = np.array([1.0, 0, 0]), np.array([0, 0, 2.0])
    R = 1.5
    cases = [
        ((lights.EMITTER_TRIANGLE, (0, 0, 0), e1, e2, 0, 0), 0.5 * 2.0 * 2 * math.pi),
        ((lights.EMITTER_POINT, (0, 0, 0), (0, 0, 0), (0, 0, 0), 0, 0), 4 * math.pi),
        ((lights.EMITTER_SPOT, (0, 0, 0), (0, -1, 0), (0, 0, 0), math.cos(0.5), math.cos(0.4)),
         2 * math.pi * (1 - math.cos(0.5))),
        ((lights.EMITTER_SUN, (0, 0, 0), (0, -1, 0), (0, 0, 0), R, 0), math.pi * R * R),
        ((lights.EMITTER_SKY, (0, 0, 0), (0, 1, 0), (0, 0, 0), R, 0), math.pi * R * R * 4 * math.pi),
        ((lights.EMITTER_SKY, (0, 0, 0), (0, 1, 0), (0, 0, 0), R, 1), math.pi * R * R * 2 * math.pi),
        ((lights.EMITTER_ENVMAP, (0, 0, 0), (0, 0, 0), (16.0, 8.0, 0), R, 0), math.pi * R * R * 4 * math.pi),
    ]
    table = lights.EnvMapLight(_two_tone_map(8, 16)).record(((0, 0, 0), R))["table"]
    for emitter, measure in cases:
        out = light_samples(cl_env, emitter, table, seed=5)
        pdf = out[:, 7].astype(np.float64)
        assert (pdf > 0).all(), emitter[0]  # every sampled direction is one the light emits
        assert abs(np.mean(1 / pdf) / measure - 1) < 0.01, emitter[0]
        np.testing.assert_allclose(np.linalg.norm(out[:, 3:6].astype(np.float64), axis=1), 1, atol=1e-5)


# -- environment map ---------------------------------------------------------------------------------------------

UPPER, LOWER = np.array([2.0, 1.0, 0.5]), np.array([0.5, 0.5, 0.5])


def _two_tone_map(h, w, split="rows"):
    """UPPER above the horizon (rows above the middle) and LOWER below; or,
    with split="columns", UPPER in the columns u < 0.5 (directions with x > 0)."""
    img = np.empty((h, w, 3))
    if split == "rows":
        img[: h // 2], img[h // 2:] = UPPER, LOWER
    else:
        img[:, : w // 2], img[:, w // 2:] = UPPER, LOWER
    return img


def _write_exr(path, img):
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(img.shape[1], img.shape[0], 3, "float"))
    out.write_image(np.ascontiguousarray(img, np.float32))
    out.close()


@pytest.fixture(scope="module")
def envmap_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("env") / "two_tone.exr"
    _write_exr(path, _two_tone_map(32, 64))
    return path


def test_environment_map_plane(envmap_file):
    """A map bright above the horizon, dim below: the plane's upper side
    receives pi UPPER, its lower side pi LOWER (each half of the map fills
    a hemisphere), through both estimators; channels as the map's colours.
    Radius 0.2, some 10^4 segments a disc: within 4%. The total power is
    pi R^2 times the map's integral, 2 pi (UPPER + LOWER), and no photon
    exceeds phi_max though their powers differ with the texels' colours."""
    eng = oclgi.Engine(_scene({"sky": {"map": str(envmap_file), "scale": 2.0}}))
    pts = on_plane([(0.0, 0.0), (0.4, -0.3), (-0.5, 0.4)])
    down = pts.copy()
    down[:, 3:] = -down[:, 3:]
    up_e = eng.irradiance(pts, method="detp", radius=0.2).irradiance.astype(np.float64)
    assert np.array_equal(eng.irradiance(pts, radius=0.2).accumulators,
                          eng.irradiance(pts, method="detp", radius=0.2).accumulators)
    down_e = eng.irradiance(down, method="detp", radius=0.2).irradiance.astype(np.float64)
    assert np.abs(up_e / (2 * math.pi * UPPER) - 1).max() < 0.04
    assert np.abs(down_e / (2 * math.pi * LOWER) - 1).max() < 0.04
    _, r = lights.bounding_sphere(eng.scene)
    np.testing.assert_allclose(eng.compiled.total_power, math.pi * r * r * 2 * 2 * math.pi * (UPPER + LOWER), rtol=1e-6)
    s, _ = eng.trace(photons=20_000)
    units = s["power"] / eng.photon_watts(20_000)
    assert units.max() <= 1 + 1e-6 and units[:, 0].max() > 0.99  # the map's reddest texels carry phi_max


def test_environment_map_orientation_is_mitsubas(tmp_path):
    """Columns u < 0.5 look along +x (Mitsuba's envmap convention): a
    vertical plane facing +x receives pi UPPER, one facing -x pi LOWER; and
    Mitsuba, given the same map, agrees on the +x side (within 2%: its
    bilinear filter blurs the map's seam by a texel)."""
    path = tmp_path / "columns.exr"
    _write_exr(path, _two_tone_map(32, 64, split="columns"))
    v = np.array([[0, -1, -1], [0, 1, -1], [0, 1, 1], [0, -1, 1]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])  # normal +x
    sc = oclgi.load_dict({"mesh": [{"vertices": v, "faces": f, "albedo": [0, 0, 0]}], "sky": {"map": str(path)},
                          "photons": {"count": 1_000_000, "seed": 2, "max_depth": 1}})
    assert np.allclose(sc.triangle_normals(), [1, 0, 0])
    eng = oclgi.Engine(sc)
    p = np.array([[0, 0, 0], [0, 0.4, -0.3]], float)
    plus = eng.irradiance(np.hstack([p, np.tile([1.0, 0, 0], (2, 1))]), radius=0.2).irradiance.astype(np.float64)
    minus = eng.irradiance(np.hstack([p, np.tile([-1.0, 0, 0], (2, 1))]), radius=0.2).irradiance.astype(np.float64)
    assert np.abs(plus / (math.pi * UPPER) - 1).max() < 0.04
    assert np.abs(minus / (math.pi * LOWER) - 1).max() < 0.04
    try:
        mitsuba_reference.load_mitsuba()
    except OclgiError:
        return
    e = mitsuba_reference.irradiance(sc, p[:1], [[1.0, 0, 0]], spp=4096, max_depth=1)
    assert np.abs(e[0] / (math.pi * UPPER) - 1).max() < 0.02


def test_environment_map_with_nan_is_refused():
    bad = _two_tone_map(4, 8)
    bad[1, 2, 0] = np.nan
    sc = _scene({"sky": {"radiance": [1, 1, 1]}}, photons=1000)
    sc.lights = [lights.EnvMapLight(bad, name="bad.exr")]
    with pytest.raises(OclgiError, match=r"sky\.map: bad\.exr: radiance must be finite"):
        oclgi.Engine(sc)


# -- the scene file ---------------------------------------------------------------------------------------------

def test_photometric_inputs_and_defaults():
    sc = _scene({"spot_light": [{"position": [0, 1, 0], "direction": [0, -2, 0], "candela": 683}],
                 "sun": [{"direction": [0, -1, 0], "lux": 683, "colour": [1, 1, 1]}]}, photons=1000)
    spot, sun = sc.lights
    np.testing.assert_allclose(spot.intensity, 1.0)
    np.testing.assert_allclose(sun.irradiance, 1.0)
    assert (spot.cone_angle, spot.cone_delta) == (lights.SPOT_CONE_ANGLE, lights.SPOT_CONE_DELTA)
    assert spot.direction == (0.0, -1.0, 0.0)  # normalised
    narrow = _scene({"spot_light": [{"position": [0, 1, 0], "direction": [0, -1, 0], "intensity": [1, 1, 1],
                                     "cone_angle": 3}]}, photons=1000).lights[0]
    assert narrow.cone_delta == 3  # the default band, within the cone
    sky = _scene({"sky": {"radiance": [1, 1, 1]}}, photons=1000).lights[0]
    assert sky.hemisphere is True and sky.up == UP


def _scene_file(tmp_path, tables: str):
    (tmp_path / "s.toml").write_text(
        "[[mesh]]\nvertices = [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]\nfaces = [[0, 2, 1], [0, 3, 2]]\n"
        "[photons]\ncount = 1000\n" + tables)
    (tmp_path / "p.csv").write_text("x,y,z,nx,ny,nz\n0,0,0,0,1,0\n")


SPOT_TABLE = "[[spot_light]]\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\nintensity = [1, 1, 1]\n"


@pytest.mark.parametrize("tables, match", [
    ("[[spot_light]]\nposition = [0, 1, 0]\nintensity = [1, 1, 1]\n", r"spot_light\[0\]\.direction: required"),
    ("[[spot_light]]\nposition = [0, 1, 0]\ndirection = [0, 0, 0]\nintensity = [1, 1, 1]\n",
     r"spot_light\[0\]\.direction: expected a non-zero direction"),
    (SPOT_TABLE + "cone_angle = 200\n", r"spot_light\[0\]\.cone_angle: expected a half-angle in \(0, 180\]"),
    (SPOT_TABLE + "cone_delta = 40\n", r"spot_light\[0\]\.cone_delta: expected degrees from 0 to cone_angle"),
    (SPOT_TABLE + "angle = 3\n", r"spot_light\[0\]: unknown key\(s\) \['angle'\]"),
    (SPOT_TABLE + "candela = 3\n", r"spot_light\[0\]: give intensity \(W/sr\) or candela, not both"),
    ("[[sun]]\ndirection = [0, -1, 0]\nirradiance = [1, -1, 1]\n", r"sun\[0\]\.irradiance"),
    ("[[sun]]\nirradiance = [1, 1, 1]\n", r"sun\[0\]\.direction: required"),
    ("[[sun]]\ndirection = [0, -1, 0]\nlux = -5\n", r"sun\[0\]\.lux: expected an illuminance > 0"),
    ("[[sun]]\ndirection = [0, -1, 0]\nirradiance = [1, 1, 1]\ncolour = [1, 1, 1]\n", r"sun\[0\]\.colour goes with lux"),
    ("[sky]\nradiance = [1, 1, 1]\nhemisphere = 1\n", r"sky\.hemisphere: expected true or false"),
    ("[sky]\nradiance = [1, 1]\n", r"sky\.radiance: expected 3"),
    ("[sky]\nradiance = [1, 1, 1]\nup = [0, 0, 0]\n", r"sky\.up: expected a non-zero direction"),
    ("[[sky]]\nradiance = [1, 1, 1]\n", r"sky: expected one \[sky\] table"),
    ("[sky]\nradiance = [1e39, 1, 1]\n", r"sky\.radiance: expected 3 numbers, each 0 or from 1\.2e-38"),
    ("[sky]\nradiance = [0, 0, 0]\n", r"the scene has no emitter"),
    ("[sky]\nmap = 'nowhere.exr'\n", r"sky\.map: image file not found: .*nowhere\.exr"),
    ("[sky]\nmap = 'p.csv'\n", r"sky\.map: cannot read"),
    ("[sky]\nmap = 'two_tone.exr'\nradiance = [1, 1, 1]\n", r"sky: map takes no radiance"),
    ("[sky]\nmap = 'two_tone.exr'\nscale = -1\n", r"sky\.scale: expected a number > 0"),
    ("[sky]\nradiance = [1, 1, 1]\nscale = 2\n", r"sky\.scale goes with map"),
])
def test_bad_light_tables_fail_in_one_line(cli_fails, tmp_path, envmap_file, tables, match):
    """Spot, sun, sky and environment-map tables (two_tone.exr beside the scene) refused in one line."""
    _scene_file(tmp_path, tables)
    shutil.copy(envmap_file, tmp_path / "two_tone.exr")
    refused_in_one_line(cli_fails, tmp_path, match)


def refused_in_one_line(cli_fails, tmp_path, match):
    """``oclgi irradiance`` of _scene_file's scene fails cleanly
    (cli_run.fails_cleanly), its error line matching ``match``."""
    cli_fails(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", "e.csv", match=match)


def test_bad_lights_made_in_python():
    sc = _scene({"sky": {"radiance": [1, 1, 1]}}, photons=1000)
    sc.lights.append(lights.SpotLight((0, 1, 0), (0, -1, 0), (1e39, 1, 1)))
    with pytest.raises(OclgiError, match=r"spot_light\[0\]\.intensity"):
        oclgi.Engine(sc)
    sc.lights[-1] = "a lamp"
    with pytest.raises(OclgiError, match=r"scene\.lights holds spot, sun and sky lights"):
        oclgi.Engine(sc)


# -- area lights facing away from everything --------------------------------------------------------------------

@pytest.mark.parametrize("facing_down", [True, False])
def test_area_light_emitting_away_from_every_surface_warns(facing_down):
    lv, lf = square(0.2, y=1.0)
    light = {"vertices": lv, "faces": lf[:, ::-1] if facing_down else lf, "albedo": [0, 0, 0], "emission": [1, 1, 1]}
    sc = _scene({}, extra_meshes=[light], photons=1000)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        eng = oclgi.Engine(sc)
    lines = [str(w.message) for w in caught if issubclass(w.category, OclgiWarning)]
    if facing_down:
        assert not lines
    else:
        assert len(lines) == 1 and "2 emitting triangle(s)" in lines[0] and "leaves the scene" in lines[0]
        s, _ = eng.trace(photons=5000)  # and indeed: every photon escapes
        assert (s["tri"] < 0).all()


# -- Mitsuba ----------------------------------------------------------------------------------------------------

def test_mitsuba_conversion_of_every_kind():
    """Mitsuba's irradiance under each converted light matches the closed
    form: the spot inside its full cone and outside it, the sun with cos
    alpha, the sky (constant, and the hemisphere envmap) with pi L."""
    try:
        mi = mitsuba_reference.load_mitsuba()
    except OclgiError:
        pytest.skip("mitsuba is not installed")
    sc = _scene({"spot_light": [SPOT]}, photons=1000)
    assert mitsuba_reference.scene_dict(mi, sc)["spot_light_0"]["type"] == "spot"
    p = np.array([[0.0, 0, 0], [0.2, 0, 0.1], [0.0, 0, 0.8]])
    n = np.tile(UP, (len(p), 1))
    e = mitsuba_reference.irradiance(sc, p, n, spp=16, max_depth=1)[:, 0]
    r = np.linalg.norm(p - [0, H, 0], axis=1)
    want = 2.0 * (H / r) / r**2
    want[2] = 0.0
    np.testing.assert_allclose(e, want, rtol=3e-3, atol=1e-6)

    sun = _scene({"sun": [{"direction": SUN_DIR, "irradiance": [2, 2, 2]}]}, photons=1000)
    e = mitsuba_reference.irradiance(sun, p[:2], n[:2], spp=16, max_depth=1)[:, 0]
    np.testing.assert_allclose(e, 2 * math.cos(ALPHA), rtol=3e-3)

    for hemisphere in (False, True):
        sky = _scene({"sky": {"radiance": [1, 1, 1], "hemisphere": hemisphere}}, photons=1000)
        kind = mitsuba_reference.scene_dict(mi, sky)["sky_0"]["type"]
        assert kind == ("envmap" if hemisphere else "constant")
        e = mitsuba_reference.irradiance(sky, p[:1], n[:1], spp=4096, max_depth=1)[:, 0]
        assert abs(e[0] / math.pi - 1) < 0.02, (hemisphere, e)


# -- glTF KHR_lights_punctual -----------------------------------------------------------------------------------

def _gltf(tmp_path, lights_ext, nodes):
    """A .gltf: a 2 x 2 floor quad (y = 0, facing up), embedded buffer, plus ``nodes`` and the lights."""
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32)
    blob = pos.tobytes() + np.array([0, 2, 1, 0, 3, 2], np.uint16).tobytes()
    children = {c for n in nodes for c in n.get("children", [])}
    doc = {
        "asset": {"version": "2.0"}, "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": lights_ext}},
        "scene": 0, "scenes": [{"nodes": [i for i in range(len(nodes) + 1) if i not in children]}],
        "nodes": [{"mesh": 0}, *nodes],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [-1, 0, -1], "max": [1, 0, 1]},
                      {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    }
    (tmp_path / "lit.gltf").write_text(json.dumps(doc))
    return tmp_path / "lit.gltf"


DOWN = [-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)]  # -90 deg about x: the node's -Z onto -Y


def test_gltf_punctual_lights(tmp_path):
    """Point, spot and directional lights, placed by their nodes (a parent's
    translation, a rotation) and by the scene file's mesh transform."""
    path = _gltf(tmp_path, [
        {"type": "point", "intensity": 683.0, "color": [1, 1, 1]},
        {"type": "spot", "intensity": 1366.0, "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.5}},
        {"type": "directional", "intensity": 683.0},
        {"type": "point", "intensity": 0.0},  # dark: dropped
    ], [
        {"translation": [0, 1, 0], "children": [5]},
        {"rotation": DOWN, "translation": [0.2, 1.5, 0], "extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"rotation": DOWN, "extensions": {"KHR_lights_punctual": {"light": 2}}},
        {"extensions": {"KHR_lights_punctual": {"light": 3}}},
        {"translation": [0.5, 0, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}},
    ])
    sc = oclgi.load_dict({"mesh": [{"path": str(path), "transform": {"translate": [0, 0.5, 0]}}],
                          "photons": {"count": 1000}})
    (point,), (spot, sun) = sc.point_lights, sc.lights
    np.testing.assert_allclose(point.position, [0.5, 1.5, 0])
    np.testing.assert_allclose(point.intensity, 1.0)
    np.testing.assert_allclose(spot.position, [0.2, 2.0, 0])
    np.testing.assert_allclose(spot.direction, [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(spot.intensity, 2.0)
    assert spot.cone_angle == pytest.approx(math.degrees(0.5))
    assert spot.cone_delta == pytest.approx(math.degrees(0.2))
    np.testing.assert_allclose(sun.direction, [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(sun.irradiance, 1.0)
    # and they light the floor: the sun alone gives 1 W/m^2, the point and spot more
    e = oclgi.Engine(sc).irradiance(on_plane([(0.0, 0.0)]) + [0, 0.5, 0, 0, 0, 0], radius=0.3, photons=200_000)
    assert e.irradiance[0, 0] > 1.0


@pytest.mark.parametrize("light, match", [
    ({"type": "area"}, r"light 0\.type: expected 'point', 'spot' or 'directional'"),
    ({"type": "spot", "spot": {"innerConeAngle": 0.6, "outerConeAngle": 0.5}}, r"light 0\.spot: expected 0 <= inner"),
    ({"type": "point", "intensity": -1}, r"light 0\.intensity: expected a number >= 0"),
    ({"type": "point", "color": [1, 1]}, r"light 0\.color: expected 3 numbers"),
])
def test_gltf_bad_lights(tmp_path, light, match):
    path = _gltf(tmp_path, [light], [{"extensions": {"KHR_lights_punctual": {"light": 0}}}])
    with pytest.raises(OclgiError, match=match):
        oclgi.load_dict({"mesh": [{"path": str(path)}], "photons": {"count": 1000}})


def test_gltf_binary_lights(tmp_path):
    """A .glb's JSON chunk is read for its lights as a .gltf's text is."""
    path = _gltf(tmp_path, [{"type": "directional", "intensity": 683.0, "color": [1, 1, 1]}],
                 [{"rotation": DOWN, "extensions": {"KHR_lights_punctual": {"light": 0}}}])
    text = path.read_bytes()
    text += b" " * (-len(text) % 4)
    glb = tmp_path / "lit.glb"
    glb.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(text)) + struct.pack("<I4s", len(text), b"JSON")
                    + text)
    (sun,) = oclgi.load_dict({"mesh": [{"path": str(glb)}], "photons": {"count": 1000}}).lights
    np.testing.assert_allclose(sun.direction, [0, -1, 0], atol=1e-12)
