"""Shared checks that an accelerated DETP variant equals plain DETP bit for bit."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
from analytic_scenes import box_mesh

import oclgi
from oclgi.cl.layout import Segment
from oclgi.estimators import ESTIMATORS
from oclgi.tracing.photon_trace import PathBatch
from oclgi.queries import QueryPoints

# Photon paths of the shared plain-DETP sums (the `plain` fixture, conftest.py).
DETP_PHOTONS = 20_000

# Disc radii as fractions of the scene's bounding-box diagonal: small, 1%, 10%.
RADIUS_FRACTIONS = (0.002, 0.01, 0.1)


def cornell_engine(scenes_dir) -> oclgi.Engine:
    return oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_box.toml"))


def bunny_engine(scenes_dir) -> oclgi.Engine:
    """The Stanford bunny (a real, fine mesh) inside a closed box lit by an area light."""
    box_v, box_f = box_mesh((-0.25, -0.05, -0.25), (0.25, 0.45, 0.25))
    light_v = np.array([[-0.05, 0.44, -0.05], [0.05, 0.44, -0.05], [0.05, 0.44, 0.05], [-0.05, 0.44, 0.05]])
    light_f = np.array([[0, 1, 2], [0, 2, 3]])  # normal -y: faces down
    return oclgi.Engine(oclgi.load_dict({
        "mesh": [
            {"path": str(scenes_dir / "stanford-bunny" / "bun_zipper.ply"), "albedo": [0.7, 0.7, 0.7]},
            {"vertices": box_v, "faces": box_f, "albedo": [0.6, 0.6, 0.6]},
            {"vertices": light_v, "faces": light_f, "albedo": [0, 0, 0], "emission": [20, 20, 20]},
        ],
        "camera": {"position": [0, 0.1, 0.24], "look_at": [0, 0.1, 0], "fov": 60, "width": 32, "height": 32},
        "photons": {"count": 20000, "seed": 5, "max_depth": 8},
    }))


def surface_samples(engine: oclgi.Engine, n: int, rng):
    """n random points on the scene's triangles (area-weighted): (positions,
    their triangle's normal to a random side, the triangles)."""
    scene = engine.scene
    areas = scene.triangle_areas()
    tri = rng.choice(len(areas), size=n, p=areas / areas.sum())
    b = rng.dirichlet([1, 1, 1], n)
    p = np.einsum("rk,rkc->rc", b, scene.vertices[scene.faces[tri]])
    return p, scene.triangle_normals()[tri] * np.where(rng.random(n) < 0.5, 1.0, -1.0)[:, None], tri


def surface_points(engine: oclgi.Engine, n: int, rng) -> oclgi.QueryPoints:
    """n random points on the scene's triangles (area-weighted), with their normals."""
    return oclgi.query_points(*surface_samples(engine, n, rng)[:2])


def check_same(ref, got, what):
    """Accumulators ``got`` (an array or an Estimate) identical to plain DETP's ``ref``."""
    got = getattr(got, "accumulators", got)
    diff = np.nonzero((ref != got).any(axis=1))[0]
    assert len(diff) == 0, f"{what}: {len(diff)} of {len(ref)} points differ from plain DETP (first {diff[:5].tolist()})"


def adversarial_batch(engine, rng, n_discs=400, n_paths=12_000, max_depth=3, offset=0.0):
    """Discs in the scene's volume and segments made to graze them: crossing
    near the rim, nearly parallel to the plane, ending just before, on or
    past it, escaping (t_end = inf), axis-aligned, and empty slots; the whole
    set moved by `offset` (float rounding far from the origin).
    Returns (points, radius, batch)."""
    lo, hi = (np.asarray(b, float) for b in engine.scene.bounds())
    d = 0.02 * engine.scene.diagonal
    x = lo + rng.random((n_discs, 3)) * (hi - lo)
    n = rng.normal(size=(n_discs, 3))
    axis = rng.random(n_discs) < 0.3
    n[axis] = np.eye(3)[rng.integers(0, 3, axis.sum())] * rng.choice([-1, 1], (axis.sum(), 1))
    n /= np.linalg.norm(n, axis=1)[:, None]
    m = n_paths * max_depth
    k = rng.integers(0, n_discs, m)
    nk = n[k]

    def tangent():
        v = rng.normal(size=(m, 3))
        v -= (v * nk).sum(1)[:, None] * nk
        return v / np.linalg.norm(v, axis=1)[:, None]

    target = x[k] + tangent() * (d * rng.choice([0.0, 0.5, 1 - 1e-6, 1.0, 1 + 1e-6, 1.001], m))[:, None]
    cos = -np.where(rng.random(m) < 0.4, 10 ** rng.uniform(-6.5, -4, m), rng.random(m))
    w = tangent() * np.sqrt(1 - cos**2)[:, None] + nk * cos[:, None]
    flat = rng.random(m) < 0.15
    w[flat, rng.integers(0, 3, flat.sum())] = 0.0
    w /= np.linalg.norm(w, axis=1)[:, None]
    back = rng.uniform(0.0, 0.5, m) * engine.scene.diagonal
    segs = np.zeros(m, Segment)
    segs["org"] = target - w * back[:, None] + offset
    segs["dir"] = w
    t_end = back * rng.choice([1 - 1e-6, 1.0, 1 + 1e-6, 0.5, 2.0], m)
    t_end[rng.random(m) < 0.1] = np.inf
    segs["t_end"] = t_end
    segs["power"] = rng.uniform(0.1, 1.0, (m, 3))
    segs["path"] = np.repeat(np.arange(n_paths), max_depth)
    ends = rng.integers(1, max_depth + 1, n_paths)
    segs[(np.arange(m) % max_depth) >= np.repeat(ends, max_depth)] = np.zeros(1, Segment)
    mf = cl.mem_flags
    buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=segs)
    lens = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=ends.astype(np.int32))
    return oclgi.query_points(x + offset, n), d, PathBatch(buf, lens, 0, n_paths, max_depth)


def run_on_batch(engine, method, points, radius, batch, count_emitted, **options):
    est = ESTIMATORS[method](engine.queue, engine.compiled, points, radius=radius, count_emitted=count_emitted,
                             **options)
    est.accumulate(batch)
    est.accumulate(batch)  # batches add up
    return est.accumulators()


def check_replace_points(engine, method):
    """Points replaced in place (a session's dynamic points) are indexed
    again: the sums equal a fresh estimator's over the new points."""
    pts, d, batch = adversarial_batch(engine, np.random.default_rng(9))
    est = ESTIMATORS[method](engine.queue, engine.compiled, pts, radius=d)
    idx = np.arange(0, len(pts), 3)
    moved, _, _ = adversarial_batch(engine, np.random.default_rng(10))  # other discs
    new = QueryPoints(moved.positions[idx], moved.normals[idx], moved.barys[idx])
    est.replace_points(idx, new)
    est.accumulate(batch)
    ref = ESTIMATORS["detp"](engine.queue, engine.compiled, est.points, radius=d)
    ref.accumulate(batch)
    assert ref.accumulators()[idx].any() and np.array_equal(est.accumulators(), ref.accumulators())


def check_variant_same_as_plain(engines, points, plain, method, scene, frac, count_emitted=True, engine=None,
                                **options):
    """``method`` (with ``options``, on ``engine``: by default the scene's
    shared one) on the shared points equals the shared plain-DETP sums
    (conftest.py); returns its estimate."""
    e = engine or engines[scene]
    est = e.irradiance(points[scene], method=method, radius=frac * e.scene.diagonal, photons=DETP_PHOTONS,
                       count_emitted=count_emitted, **options)
    check_same(plain(scene, frac, count_emitted), est, f"{scene} radius {frac} x diagonal {options}")
    return est


def check_adversarial(engine, method, seed, count_emitted, cases, **batch):
    """``method`` with each of ``cases`` (option dicts) sums bit for bit what
    plain DETP sums on adversarial_batch's segments (``batch``: its sizes)."""
    pts, d, b = adversarial_batch(engine, np.random.default_rng(seed), **batch)
    ref = run_on_batch(engine, "detp", pts, d, b, count_emitted)
    assert (ref != 0).any(axis=1).sum() > 0.5 * len(pts)
    for opts in cases:
        got = run_on_batch(engine, method, pts, d, b, count_emitted, **opts)
        assert np.array_equal(got, ref), f"{opts} {batch}: {(got != ref).any(axis=1).sum()} discs differ"


def check_camera_misses(engine, method, size=24, cases=({},)):
    """Camera points include background pixels (zero normals): an index
    leaves them out, and they stay zero, as in plain DETP (``method`` with
    each of ``cases``, option dicts)."""
    pts = engine.camera_points(width=size, height=size)
    assert (pts.tri < 0).any()
    ref = engine.irradiance(pts, method="detp", radius=0.05, photons=DETP_PHOTONS)
    for opts in cases:
        est = engine.irradiance(pts, method=method, radius=0.05, photons=DETP_PHOTONS, **opts)
        check_same(ref.accumulators, est, f"camera points {opts}")
