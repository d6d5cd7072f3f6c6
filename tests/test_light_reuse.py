"""Moving lights by path reuse (oclgi/tracing/light_reuse.py, kernels/light_reuse.cl).

Unbiasedness: each frame's mean over many seeds against an independent
per-frame computation (a fresh Engine with the light at that position,
Engine.irradiance), a two-sample z-test per point and frame with a
Bonferroni correction: the family of F x P tests has a false-alarm rate of
at most ALPHA, so each test is run at ALPHA / (F x P). Variances are
reported, not asserted tightly. Bit-exactness: the same seed gives the same
frames (the int64 sums) whatever the batch split or the work-group size.
"""

import re
from statistics import NormalDist

import numpy as np
import pyopencl as cl
import pytest
from cli_run import in_process
from conftest import SCENES
from reference import ray_triangle_brute

import oclgi
from oclgi.cl.layout import Segment
from oclgi.errors import OclgiError
from oclgi.tracing.light_reuse import LightReuse, light_path
from oclgi.tracing.light_reweight import Reweighting

BOX = str(SCENES / "cornell-box" / "CornellBox-Original.obj")
ALPHA = 1e-3  # family-wise false-alarm rate of each unbiasedness test
POSITIONS = np.array([[-0.5, 1.5, 0.0], [0.5, 1.6, 0.2], [0.0, 1.8, -0.4], [0.3, 1.1, 0.5]])
AXES = np.array([[0.0, -1.0, 0.0], [-0.3, -1.0, 0.0], [0.2, -1.0, 0.3], [0.0, -1.0, -0.4]])


def box(position, spot=None, name="lamp", photons=20_000, max_depth=6):
    """The Cornell box lit by one point light (or a spot with axis ``spot``), its area light off."""
    light = {"name": name, "position": [float(c) for c in position], "intensity": [1.0, 0.8, 0.6]}
    tables = ({"spot_light": [{**light, "direction": [float(c) for c in spot], "cone_angle": 50.0,
                               "cone_delta": 15.0}]} if spot is not None else {"point_light": [light]})
    return oclgi.load_dict({"mesh": [{"path": BOX, "materials": {"light": {"emission": [0, 0, 0]}}}], **tables,
                            "photons": {"count": photons, "seed": 1, "max_depth": max_depth}})


def points(n_floor=10, n_wall=6):
    """Query points on the floor and the back wall, clear of the edges by more than the radius."""
    r = np.random.default_rng(7)
    floor = [[x, 0.0, z, 0, 1, 0] for x, z in r.uniform([-0.85, -0.85], [0.85, 0.75], (n_floor, 2))]
    wall = [[x, y, -1.04, 0, 0, 1] for x, y in r.uniform([-0.8, 0.2], [0.8, 1.8], (n_wall, 2))]
    return np.array(floor + wall)


RADIUS = 0.12
N = 1500  # paths per position
SEEDS = 20


def _frames(engine, seed, axes=None, method="detp_disc_index", **kw):
    reuse = LightReuse(engine, "lamp", POSITIONS, axes, photons=N, seed=seed, max_depth=6, **kw)
    return [e.irradiance.sum(axis=1) for e in reuse.frames_irradiance(points(), method=method, radius=RADIUS)]


@pytest.mark.parametrize("kind, method", [("point", "detp_disc_index"), ("spot", "detp_disc_index"),
                                          ("spot", "impact")])
def test_each_frame_is_unbiased(kind, method):
    spot = kind == "spot"
    axes = AXES if spot else None
    engine = oclgi.Engine(box(POSITIONS[0], AXES[0] if spot else None))
    reuse = np.array([_frames(engine, 1000 + s, axes, method) for s in range(SEEDS)])  # (seeds, F, P)
    ref = []
    for j in range(len(POSITIONS)):
        eng = oclgi.Engine(box(POSITIONS[j], AXES[j] if spot else None))
        ref.append([eng.irradiance(points(), method=method, photons=len(POSITIONS) * N, radius=RADIUS, seed=1 + s,
                                   max_depth=6).irradiance.sum(axis=1) for s in range(SEEDS)])
    ref = np.array(ref).transpose(1, 0, 2)  # (seeds, F, P): equal path counts per frame
    _z_tests(f"{kind}, {method}", reuse, ref)


def _z_tests(label, reuse, ref):
    """Two-sample z-tests of the frames (seeds, F, P) against their
    recomputations, per point and frame, Bonferroni-corrected; and the
    tests' power to see a wrong frame."""
    seeds = len(reuse)
    m1, m2 = reuse.mean(0), ref.mean(0)
    v1, v2 = reuse.var(0, ddof=1), ref.var(0, ddof=1)
    se = np.sqrt(v1 / seeds + v2 / seeds)
    lit = se > 0  # points that no position lights are 0 in both
    z = np.abs(m1 - m2)[lit] / se[lit]
    z_crit = NormalDist().inv_cdf(1 - ALPHA / (2 * z.size))
    ratio = v1 / np.maximum(v2, 1e-30)
    print(f"\n{label}: {z.size} tests, max |z| {z.max():.2f} (Bonferroni critical {z_crit:.2f}); "
          f"variance reuse / recompute per frame (median over points, equal paths): "
          f"{[float(np.median(ratio[j][lit[j]])) for j in range(len(m1))]}")
    assert lit.sum() >= 0.8 * lit.size
    assert z.max() < z_crit, f"|z| = {z.max():.2f} at {np.argwhere(lit)[np.argmax(z)]}"
    assert np.isfinite(ratio[lit]).all()
    # the test has the power to see a wrong frame: each against its neighbour's recomputation
    z_wrong = np.abs(m1 - np.roll(m2, 1, axis=0)) / np.sqrt(v1 / seeds + np.roll(v2, 1, axis=0) / seeds + 1e-30)
    assert z_wrong.max() > 3 * z_crit


def _sums(engine, seed=5, batch_paths=None, method="detp_disc_index", axes=None):
    reuse = LightReuse(engine, "lamp", POSITIONS, axes, photons=900, seed=seed, max_depth=6, batch_paths=batch_paths)
    est = reuse.estimator(points(), method=method, radius=RADIUS)
    return [reuse.estimate(j, est).accumulators for j in range(reuse.frames)]


@pytest.mark.parametrize("method", ["detp_disc_index", "detp", "photon_map", "impact"])
def test_frames_are_bit_exact_whatever_the_split_or_local_size(method):
    sc = box(POSITIONS[0], AXES[0])
    a = _sums(oclgi.Engine(sc), method=method, axes=AXES)
    b = _sums(oclgi.Engine(sc, local_size=16), batch_paths=517, method=method, axes=AXES)
    for x, y in zip(a, b):
        assert x.dtype == np.int64 and np.array_equal(x, y)
    assert not np.array_equal(a[0], a[1]), "the frames should differ"
    assert not np.array_equal(a[0], _sums(oclgi.Engine(sc), seed=6, method=method, axes=AXES)[0])


def test_one_position_is_the_ordinary_run():
    """F = 1: every weight is p / p = 1 and a point light's profile is 1, so
    the tails are the ordinary run's bit for bit, and the first hits carry
    the ordinary photon's power: Impact Count's sums are the same."""
    eng = oclgi.Engine(box(POSITIONS[1]))
    pts = points()
    reuse = LightReuse(eng, "lamp", POSITIONS[1:2], photons=3000, seed=9, max_depth=6)
    est = reuse.frames_irradiance(pts, method="impact")[0]
    ref = eng.irradiance(pts, method="impact", photons=3000, seed=9, max_depth=6)
    assert np.array_equal(est.accumulators, ref.accumulators)


def _smoothstep(x, a, b):
    t = np.clip((x - a) / (b - a), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def test_weights_and_powers_match_a_float64_reference():
    """The kernels' densities (light_pdf_dir to area, visibility, side),
    their sums D and a frame's powers against numpy in float64, with the
    shadow rays by brute force over every triangle."""
    sc = box(POSITIONS[0], AXES[0])
    eng = oclgi.Engine(sc)
    reuse = LightReuse(eng, "lamp", POSITIONS, AXES, photons=400, seed=4, max_depth=6)
    md, n_paths = reuse.max_depth, reuse.n_paths
    store = np.empty(n_paths * md, Segment)
    cl.enqueue_copy(eng.queue, store, reuse.store)
    D = np.empty(n_paths, np.float32)
    cl.enqueue_copy(eng.queue, D, reuse.density_sum)
    bits = np.empty(n_paths * reuse.words, np.uint32)
    cl.enqueue_copy(eng.queue, bits, reuse.visible)
    s0 = store[::md]
    hit = s0["tri"] >= 0
    x = s0["org"].astype(np.float64) + np.where(hit, s0["t_end"], 1.0)[:, None] * s0["dir"]  # escaped: anywhere
    normals = sc.triangle_normals()[np.maximum(s0["tri"], 0)]
    side = np.sign(np.einsum("ij,ij->i", normals, s0["dir"]))
    tri_v = sc.vertices[sc.faces]
    rec = reuse.records
    a, b = float(rec["a"][0]), float(rec["b"][0])
    p = np.zeros((n_paths, reuse.frames))
    for l in range(reuse.frames):
        v = x - rec["p"][l]
        r = np.linalg.norm(v, axis=1)
        d = v / r[:, None]
        c = np.einsum("ij,ij->i", normals, d)
        ct = d @ rec["e1"][l]
        pdf = np.where(ct >= a, 1.0 / (2 * np.pi * (1 - a)), 0.0)
        t, tri = ray_triangle_brute(np.broadcast_to(rec["p"][l], d.shape), d, tri_v)
        own = s0["path"] // reuse.paths_per_position == l  # the path's own position hit x
        seen = own | ~(t < r - eng.compiled.eps)  # else: nothing in the way short of x
        p[:, l] = np.where(hit & (c * side > 0) & seen, pdf * np.abs(c) / r**2, 0.0)
    got_bits = ((bits.reshape(n_paths, reuse.words)[:, 0][:, None] >> np.arange(reuse.frames)) & 1).astype(bool)
    agree = (got_bits == (p > 0)).all(axis=1)
    assert agree.mean() > 0.995 and hit.mean() > 0.5
    assert np.allclose(D[agree], p[agree].sum(axis=1), rtol=1e-4, atol=0)
    j = 2
    out = np.concatenate([bt.read_segments(eng.queue) for bt in reuse.batches(j)])  # each read before the next
    d_j = x - rec["p"][j]
    d_j /= np.linalg.norm(d_j, axis=1)[:, None]
    w = np.divide(p[:, j], p.sum(axis=1), out=np.zeros(n_paths), where=p.sum(axis=1) > 0)
    c0 = _smoothstep(d_j @ rec["e1"][j], a, b) * w
    k = s0["path"] // reuse.paths_per_position
    traced = _smoothstep(np.einsum("ij,ij->i", s0["dir"], rec["e1"][k]), a, b)
    scale = np.divide(c0, traced, out=np.zeros(n_paths), where=traced > 0)
    ok = agree & (p[:, j] > 0)
    e = rec["power"][0].astype(np.float64)
    assert np.allclose(out["power"][::md][ok], c0[ok, None] * e, rtol=2e-4, atol=1e-7)
    assert np.allclose(out["org"][::md][ok], rec["p"][j], atol=0)
    tails = out.reshape(n_paths, md)[ok, 1:]["power"]
    assert np.allclose(tails, store.reshape(n_paths, md)[ok, 1:]["power"] * scale[ok, None, None], rtol=2e-4, atol=1e-7)
    assert (out.reshape(n_paths, md)[~(p[:, j] > 0) & agree]["dir"] == 0).all()  # unseen: empty paths


def test_powers_stay_under_phi_max():
    eng = oclgi.Engine(box(POSITIONS[0], AXES[0]))
    reuse = LightReuse(eng, "lamp", POSITIONS, AXES, photons=800, seed=3, max_depth=6)
    for j in range(reuse.frames):
        for batch in reuse.batches(j):
            seg = batch.read_segments(eng.queue)
            assert seg["power"].max() <= 1.0 + 1e-6 and np.isfinite(seg["power"]).all()


def test_light_path_specs(tmp_path):
    p, d = light_path("0,1,0;1,1,0", frames=3)
    assert np.allclose(p, [[0, 1, 0], [0.5, 1, 0], [1, 1, 0]]) and d is None
    np.save(tmp_path / "k.npy", np.array([[0, 1, 0, 0, -2, 0], [1, 1, 0, 0, -1, 0]]))
    p, d = light_path(str(tmp_path / "k.npy"), frames=2)
    assert np.allclose(d, [[0, -1, 0], [0, -1, 0]])
    for bad, match in [("0,1", "rows of 3"), ("a,b,c", "expected x,y,z"), ("0,1,0;1,1", "as many numbers"),
                       ("0,1,0,0,0,0", "direction is zero"), ("nan,1,0", "finite"),
                       (str(tmp_path / "none.npy"), "no such file")]:
        with pytest.raises(OclgiError, match=match):
            light_path(bad, frames=2)


def test_api_errors():
    eng = oclgi.Engine(box(POSITIONS[0]))
    with pytest.raises(OclgiError, match="no point or spot light of that name"):
        LightReuse(eng, "nope", POSITIONS, photons=10)
    with pytest.raises(OclgiError, match="index below 1"):
        LightReuse(eng, 3, POSITIONS, photons=10)
    with pytest.raises(OclgiError, match="a spot light's"):
        LightReuse(eng, "lamp", POSITIONS, AXES, photons=10)
    with pytest.raises(OclgiError, match="rows of 3"):
        LightReuse(eng, 0, POSITIONS[:, :2], photons=10)
    r = LightReuse(eng, 0, POSITIONS[:2], photons=10)
    with pytest.raises(OclgiError, match="frame must be an index below 2"):
        next(r.batches(2))
    area = oclgi.Engine(oclgi.load_dict({"mesh": [{"path": BOX}],
                                         "point_light": [{"name": "lamp", "position": [0, 1, 0],
                                                          "intensity": [1, 1, 1]}]}))
    with pytest.raises(OclgiError, match="only emitter"):
        LightReuse(area, "lamp", POSITIONS, photons=10)
    with pytest.raises(OclgiError, match="name: expected a non-empty string"):
        oclgi.load_dict({"mesh": [{"path": BOX}], "point_light": [{"name": 3, "position": [0, 1, 0],
                                                                   "intensity": [1, 1, 1]}]})


SCENE_TOML = f"""
[[mesh]]
path = "{BOX}"
materials = {{ light = {{ emission = [0, 0, 0] }} }}

[[point_light]]
name = "lamp"
position = [0.0, 1.5, 0.0]
intensity = [1, 1, 1]

[camera]
position = [0.0, 1.0, 3.94]
look_at = [0.0, 1.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 39.3
width = 24
height = 24

[photons]
count = 4000
max_depth = 5

[estimator]
radius = 0.1
"""


def test_cli_animates_a_light(monkeypatch, capsys, tmp_path):
    scene = tmp_path / "lamp.toml"
    scene.write_text(SCENE_TOML)
    out = tmp_path / "out"
    r = in_process(monkeypatch, capsys, tmp_path, "animate", str(scene), "--light", "lamp", "--light-path=-0.5,1.5,0;0.5,1.5,0", "--frames", "3",
                "--photons", "1000", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["frame_0000.png", "frame_0001.png", "frame_0002.png", "timing.csv"]
    rows = (out / "timing.csv").read_text().splitlines()
    assert rows[0].startswith("frame,paths,trace_s") and len(rows) == 4


@pytest.mark.parametrize("args, match", [
    (["--light", "nope", "--light-path", "0,1.5,0"], "no point or spot light of that name"),
    (["--light", "lamp"], "has no path in the scene file: give --light-path"),
    (["--light-path", "0,1.5,0"], "--light-path needs --light"),
    (["--light", "lamp", "--light-path", "0,1.5"], "rows of 3"),
    (["--light", "lamp", "--light-path", "0,1.5,0", "--path", "line:1,0,0"], "go with objects"),
    (["--light", "lamp", "--light-path", "missing.npy"], "no such file"),
    ([], "needs --path"),
])
def test_cli_errors_are_one_line(cli_fails, tmp_path, args, match):
    scene = tmp_path / "lamp.toml"
    scene.write_text(SCENE_TOML)
    cli_fails(tmp_path, "animate", str(scene), *args, "--frames", "2", "-o", str(tmp_path / "out"), match=re.escape(match),
              alone=True)


SPONZA_POSITIONS = np.array([[0.0, 6.0, 0.0], [-5.0, 5.0, 1.0], [4.0, 7.0, -1.0], [8.0, 4.0, 0.5]])


def _sponza_points(scene, n=24):
    """Points on Sponza's floor and lower walls, area-weighted, seed fixed."""
    r = np.random.default_rng(3)
    nrm = scene.triangle_normals()
    v = scene.vertices[scene.faces]
    centre = v.mean(axis=1)
    area = scene.triangle_areas()
    floor = np.nonzero((nrm[:, 1] > 0.99) & (centre[:, 1] < 0.5) & (area > 0.05))[0]
    tri = r.choice(floor, n, p=area[floor] / area[floor].sum())
    b = r.dirichlet([3, 3, 3], n)  # away from the triangles' edges
    p = np.einsum("rk,rkc->rc", b, v[tri])
    return np.hstack([p, nrm[tri]])


def test_each_frame_is_unbiased_in_sponza(scenes_dir):
    """The same z-tests on a real scene: Sponza's atrium (66k triangles),
    its point light moved among four positions."""
    scene = oclgi.load_file(scenes_dir / "sponza.toml")
    engine = oclgi.Engine(scene)
    pts = _sponza_points(scene)
    n, seeds, radius = 2500, 12, 0.5
    reuse = []
    for s in range(seeds):
        lr = LightReuse(engine, 0, SPONZA_POSITIONS, photons=n, seed=500 + s, max_depth=5)
        reuse.append([e.irradiance.sum(axis=1) for e in lr.frames_irradiance(pts, radius=radius)])
    reuse = np.array(reuse)
    ref = []
    for j, pos in enumerate(SPONZA_POSITIONS):
        scene.point_lights[0].position = tuple(pos)
        eng = oclgi.Engine(scene)
        ref.append([eng.irradiance(pts, photons=len(SPONZA_POSITIONS) * n, radius=radius, seed=1 + s,
                                   max_depth=5).irradiance.sum(axis=1) for s in range(seeds)])
    _z_tests("Sponza", reuse, np.array(ref).transpose(1, 0, 2))


@pytest.mark.parametrize("spot", [False, True], ids=["point", "spot"])
@pytest.mark.parametrize("consistent", [False, True], ids=["standard", "consistent"])
def test_reweighted_frames_equal_the_frames(spot, consistent):
    """A frame as segment 0 plus the stored tail pairs re-weighted
    (oclgi/tracing/light_reweight.py) has the frame's sums bit for bit."""
    axes = AXES if spot else None
    engine = oclgi.Engine(box(POSITIONS[0], AXES[0] if spot else None))
    reuse = LightReuse(engine, "lamp", POSITIONS, axes, photons=1200, seed=9, max_depth=6)
    full = reuse.estimator(points(), radius=RADIUS, consistent=consistent)
    est = reuse.estimator(points(), radius=RADIUS, consistent=consistent)
    rw = Reweighting(reuse, est)
    assert rw.n_pairs > 20
    for j in (1, 0, 3, 2, 1):
        a = reuse.estimate(j, full)
        b = reuse.estimate(j, est, reweighting=rw)
        assert np.array_equal(a.accumulators, b.accumulators), j
        np.testing.assert_array_equal(a.irradiance, b.irradiance)
    with pytest.raises(OclgiError, match="detp_disc_index"):
        Reweighting(reuse, reuse.estimator(points(), method="detp", radius=RADIUS))
    with pytest.raises(OclgiError, match="another animation or estimator"):
        reuse.estimate(0, full, reweighting=rw)


@pytest.mark.parametrize("spot", [False, True], ids=["point", "spot"])
def test_exact_direct_light_follows_the_frame(spot):
    """With direct = "exact" each frame's direct term (exact direct minus
    the same estimator without the light's own segments) is the one a fresh
    engine with the light at that frame's position computes: the resolve
    reads the frame's light, not the one loaded."""
    axes = AXES if spot else None
    engine = oclgi.Engine(box(POSITIONS[0], AXES[0] if spot else None))
    reuse = LightReuse(engine, "lamp", POSITIONS, axes, photons=1200, seed=9, max_depth=6)
    exact = reuse.estimator(points(), radius=RADIUS, direct="exact")
    indirect = reuse.estimator(points(), radius=RADIUS, count_emitted=False)
    seen = []
    for j in (2, 0, 3, 1):
        direct = reuse.estimate(j, exact).irradiance - reuse.estimate(j, indirect).irradiance
        fresh = oclgi.Engine(box(POSITIONS[j], AXES[j] if spot else None))
        kw = dict(method="detp_disc_index", photons=1200, seed=9, max_depth=6, radius=RADIUS)
        want = (fresh.irradiance(points(), direct="exact", **kw).irradiance
                - fresh.irradiance(points(), count_emitted=False, **kw).irradiance)
        assert want.max() > 0.05
        np.testing.assert_allclose(direct, want, rtol=1e-4, atol=1e-5 * want.max())
        seen.append(direct)
    assert not np.allclose(seen[0], seen[1], rtol=0.05)  # the frames' direct light differs
