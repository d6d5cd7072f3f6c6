"""The estimator study: bias, variance, cost and efficiency of the estimators
against a reference and against their theoretical variance bounds.

>>> from oclgi.study import Config, run_study, equal_time       # doctest: +SKIP
>>> res = run_study(engine, [Config("detp_disc_index", [1e5, 4e5], radius=0.03),
...                          Config("photon_map", [1e5, 4e5], k=50),
...                          Config("impact", [1e5, 1e6])],
...                 points="random:300", seeds=8, reference="detp")
>>> res.write("out/study")          # study.md, study.csv and the two plots
>>> equal_time(res).rows            # error of each estimator at a common time

A configuration is a method, its parameters and one or more photon counts;
each (configuration, photon count) is run with R seeds (randomness is a pure
function of the seed) and gives one row of the table. Per point and colour
channel, over the seeds: the mean, the unbiased sample variance, the bias
(mean minus reference) and the RMSE against the reference. Summaries over
the points (and channels) whose reference is positive and known to 10%
(REFERENCE_TRUST) are relative, so that bright and dim points weigh alike:

- rel_bias: mean of bias / ref; rel_bias_se its standard error, from the
  spread of the per-seed means over the points (which keeps the correlation
  between nearby points) and the reference's own error;
- rms_bias: the RMS of bias / ref over the points with the seeds' noise
  (var / R) and the reference's removed: what is left is the systematic part;
- rel_var: mean of var / ref^2; rel_rmse: sqrt of the mean of MSE / ref^2,
  less the reference's own relative variance (an independent reference adds
  its variance to the expected squared error; what is left is the error
  against the reference's expectation, its bias included);
- time_s: the median over the seeds of a run's total seconds (trace and
  estimate, setup excluded; each method is warmed up once first, so program
  builds are not timed); estimate_s: the median of total minus trace (the
  estimator's build, accumulation and resolve: Photon Maps' search runs in
  resolve);
- the same over the points in absolute terms, divided by the mean
  reference (or its square) so as not to depend on units: nbias = mean bias
  / mean ref, nvar = mean var / mean ref^2, nrmse = sqrt(mean MSE, less the
  reference's variance) / mean ref. These weigh points by their irradiance,
  so a few dim points (a shadow edge, a corner, where a relative error can
  reach hundreds of percent) do not decide them, as they can decide the
  relative means; nrmse is what the equal-time comparison uses by default;
- efficiency = 1 / (time_s x nvar), per second (DESIGN.md section 3: the
  variance, here over the squared mean reference, a constant of the scene,
  so that it does not depend on units);
- the theoretical bound and the measured Var(L_hat) = (rho / pi)^2 Var(E_hat)
  per point (see oclgi/study/bound_inputs.py for what is bounded and every input):
  var_L and bound (means over the points), bound_ratio_mean and
  bound_ratio_max (measured over bound), under_bound (the fraction of
  points and channels whose sample variance is under the bound).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .. import budget, params, queries
from ..budget import KNN_METHODS
from ..engine import as_query_points
from ..errors import OclgiError
from ..estimators import check_options
from ..progress import Progress
from . import bound_inputs as study_bounds
from . import reference as study_reference
from .stats import REFERENCE_TRUST

WARMUP_PHOTONS = 20_000


class Config:
    """One estimator configuration: ``method``, its photon counts, the DETP
    ``radius`` (None: the scene's) and the method's options (``k``,
    ``estimator``, ``leaf_size``, ...; also ``extension`` and
    ``count_emitted``), all checked by oclgi/params.py."""

    def __init__(self, method: str, photons, radius: float | None = None, **options):
        self.method = params.method(method)
        self.photons = tuple(sorted(set(params.photon_counts(photons))))
        self.radius = None if radius is None else params.radius(radius)
        own = {k: v for k, v in options.items() if k not in params.OPTION_PARAMS}
        check_options(self.method, own)
        self.options = {k: params.option(k, v) for k, v in options.items()}

    @property
    def is_detp(self) -> bool:
        return self.method.startswith("detp")

    def label(self, scene_radius: float | None = None) -> str:
        """The configuration without its photon counts: a curve in the plots."""
        parts = [self.method]
        if self.is_detp:
            r = self.radius if self.radius is not None else scene_radius
            if r is not None:
                parts.append(f"d={r:.4g}")
        if self.method in KNN_METHODS:
            parts.append(f"k={self.options.get('k', study_bounds.DEFAULT_K)}")
            parts.append(str(self.options.get("estimator", "k-1")))
        parts += [f"{k}={v}" for k, v in sorted(self.options.items()) if k not in ("k", "estimator")]
        return " ".join(parts)

    def __repr__(self):
        return f"Config({self.label()!r}, photons={list(self.photons)})"


# -- query points ------------------------------------------------------------------


def study_points(engine, points, seed: int = 0) -> queries.QueryPoints:
    """Query points from a spec: a QueryPoints or (n, 6) array, a ``.npy`` or
    ``.csv`` file of them, ``"vertices"``,
    ``"camera"`` or ``"camera:WxH"`` (the visible point of each pixel),
    ``"random:N"`` or an int N (N points uniform over the surface area, drawn
    with ``seed``, each facing the side its triangle's normal gives)."""
    from pathlib import Path

    if isinstance(points, (int, np.integer)) and not isinstance(points, bool):
        points = f"random:{points}"
    if isinstance(points, (str, Path)) and Path(points).suffix.lower() in (".npy", ".csv"):
        return queries.from_file(points)
    if isinstance(points, str):
        kind, _, arg = points.partition(":")
        if kind == "vertices" and not arg:
            return engine.vertex_points()
        if kind == "camera":
            w = h = None
            if arg:
                try:
                    w, h = (int(x) for x in arg.lower().split("x"))
                except ValueError:
                    raise OclgiError(f"points {points!r}: expected camera:WIDTHxHEIGHT") from None
            return engine.camera_points(width=w, height=h)
        if kind == "random":
            n = _random_count(points)
            budget.check(budget.random_points_need(n))
            return random_surface_points(engine.scene, n, np.random.default_rng(seed))
        raise OclgiError(f"unknown points {points!r}: use vertices, camera[:WxH], random:N, "
                         "a points file or an (n, 6) array")
    return as_query_points(points)


def _random_count(spec: str) -> int:
    """N of ``random:N`` (``random:2e5`` as ``--photons 2e5`` is read)."""
    n = params.integral(params.number_text(spec.partition(":")[2]))
    if n is None or n < 1:
        raise OclgiError(f"points {spec!r}: expected random:N with N a positive integer")
    return n


def points_total(engine, points) -> int | None:
    """How many query points ``points`` (a spec of :func:`study_points`)
    gives, known before they are made: None for a points file (its size is
    what is on disk) or a spec study_points will refuse."""
    if isinstance(points, queries.QueryPoints):
        return len(points)
    if isinstance(points, (int, np.integer)) and not isinstance(points, bool):
        return int(points) if points > 0 else None
    if isinstance(points, str):
        kind, _, arg = points.partition(":")
        if kind == "vertices":
            return len(engine.scene.vertices)
        if kind == "random":
            return _random_count(points)
        if kind == "camera":
            cam = engine.scene.camera
            if arg:
                try:
                    w, h = (params.image_size(params.number_text(x), "points camera:WxH")
                            for x in arg.lower().split("x"))
                except ValueError:
                    return None
                return w * h
            return cam.width * cam.height if cam is not None else None
        return None
    shape = getattr(points, "shape", None)
    return int(shape[0]) if shape else None


def random_surface_points(scene, n: int, rng, triangles=None) -> queries.QueryPoints:
    """n points uniform over the scene's area (or over ``triangles``, an
    index array), on the side of their triangle's normal (the side a mesh
    shows: inside a box whose faces face in), with their triangle and
    barycentrics, as Impact Count needs."""
    candidates = np.arange(scene.n_triangles) if triangles is None else np.asarray(triangles)
    areas = scene.triangle_areas()[candidates]
    tri = candidates[rng.choice(len(areas), size=n, p=areas / areas.sum())]
    b = rng.dirichlet([1.0, 1.0, 1.0], n)
    p = np.einsum("rk,rkc->rc", b, scene.vertices[scene.faces[tri]])
    q = queries.from_arrays(p, scene.triangle_normals()[tri])
    q.positions[:, 3] = tri.astype(np.int32).view(np.float32)
    q.barys[:] = b[:, 1:]
    q.kind = "random"
    return q


def _located(engine, points, need: bool):
    """Points with the triangle under each found where it is unknown (the
    albedo at a point, and Impact Count, need it). When some point is off the
    surface, that is an error only if an Impact Count run ``need``s it."""
    from ..estimators.impact_count import locate

    if points.kind == "camera" or not (points.tri < 0).any():
        return points
    try:
        return locate(engine.queue, engine.compiled, points)
    except OclgiError:
        if need:
            raise
        return points


# -- results -------------------------------------------------------------------------


@dataclass
class Row:
    """One configuration at one photon count, over the seeds."""

    config: Config
    label: str
    photons: int
    radius: float | None
    irradiance: np.ndarray  # (R, n, 3) float64, one estimate per seed
    seconds: np.ndarray  # (R,) total seconds per run
    estimate_seconds: np.ndarray  # (R,) total minus trace
    segments: float  # mean over the seeds
    bound: np.ndarray  # (n, 3) bound on Var(L_hat); NaN where it does not apply
    summary: dict = field(default_factory=dict)

    @property
    def mean(self) -> np.ndarray:
        return self.irradiance.mean(axis=0)

    @property
    def variance(self) -> np.ndarray:
        return self.irradiance.var(axis=0, ddof=1)


@dataclass
class StudyResult:
    scene_name: str
    points: queries.QueryPoints
    seeds: list
    reference: study_reference.ReferenceValues
    inputs: study_bounds.BoundInputs
    albedo: np.ndarray  # (n, 3) albedo under each point (R_max where unknown)
    rows: list
    seconds: float = 0.0

    @property
    def valid(self) -> np.ndarray:
        """(n, 3): the relative statistics' domain, the point-channels whose
        reference is positive and known to REFERENCE_TRUST (a dim point whose
        reference is a few photons would divide by noise)."""
        return trusted(self.reference)

    def table(self) -> list[dict]:
        return [r.summary for r in self.rows]

    def families(self) -> dict:
        """label -> rows in photon order (a configuration's curve)."""
        out: dict = {}
        for r in self.rows:
            out.setdefault(r.label, []).append(r)
        return out

    # writers (oclgi/study/report.py, imported when one is used)
    def _repr_html_(self) -> str:
        """The table, shown inline by Jupyter."""
        return _report().html_table(self)

    def to_markdown(self) -> str:
        return _report().markdown(self)

    def to_csv(self) -> str:
        return _report().csv_text(self)

    def to_json(self) -> dict:
        return _report().json_dict(self)

    def write(self, out_dir, stem: str = "study", plots: bool = True) -> list:
        """Write ``stem.md``, ``stem.csv`` and (``plots``) ``error_vs_time.png``
        and ``variance_vs_photons.png`` into ``out_dir``, all or nothing."""
        return _report().write_all(self, out_dir, stem, plots)


def _report():
    from . import report

    return report


# -- the study -------------------------------------------------------------------------


def seed_total(seeds) -> int:
    """How many seeds ``seeds`` (a count R, or a list) gives, checked as a
    count (at least 2, a list of them fits in memory) without making the list."""
    if np.isscalar(seeds) or isinstance(seeds, (str, bytes)):
        n = params.integral(seeds)
        if n is None:
            raise OclgiError(f"seeds must be a count (an integer, at least 2) or a list of integers, got {seeds!r}")
        if n < 2:
            raise OclgiError(f"the study needs at least 2 seeds for a variance, got {seeds}")
        params.seed_count(n, "seeds")
        budget.check(budget.seeds_need(n))
        return n
    try:
        return len(seeds)
    except TypeError:
        raise OclgiError(f"seeds must be a count (an integer, at least 2) or a list of integers, got {seeds!r}") \
            from None


def check_seeds(seeds) -> list:
    if np.isscalar(seeds) or isinstance(seeds, (str, bytes)):
        return list(range(1, seed_total(seeds) + 1))
    seeds = list(seeds)
    for s in seeds:
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not 0 <= s < study_reference.REFERENCE_SEED_BASE:
            raise OclgiError(f"seeds must be integers in 0..2^40-1, got {s!r}")
    if len(set(seeds)) < 2 or len(set(seeds)) != len(seeds):
        raise OclgiError(f"the study needs at least 2 distinct seeds, got {seeds}")
    return [int(s) for s in seeds]


def trusted(ref) -> np.ndarray:
    """(n, 3): reference values that are positive and known to REFERENCE_TRUST."""
    return np.isfinite(ref.values) & (ref.values > 0) & (ref.std_error <= REFERENCE_TRUST * ref.values)


def run_study(engine, configs, points="random:256", seeds=8, reference=None, point_seed: int = 0,
              bound_params: dict | None = None, progress: bool | None = None) -> StudyResult:
    """Run every configuration at every photon count with every seed.

    ``points``: see :func:`study_points`. ``seeds``: a count R >= 2 (seeds
    1..R) or a list. ``reference``: an (n, 3) array, a callable
    ``f(positions, normals)``, ``"detp"``/``"detp:PHOTONS"``/``"mitsuba"``
    or a :class:`oclgi.study.reference.Reference` (default: high-photon
    DETP). ``bound_params``: ``l_max`` and/or ``r_max`` overriding what is
    read off the scene (oclgi/study/bound_inputs.py).
    """
    t_start = time.perf_counter()
    configs = list(configs)
    if not configs:
        raise OclgiError("the study needs at least one configuration")
    for c in configs:
        if not isinstance(c, Config):
            raise OclgiError(f"configurations must be oclgi.study.Config, got {c!r}")
    n_points = points_total(engine, points)
    if n_points is not None:  # a study too large for the host is refused before any list or point is made
        budget.check(budget.study_need(n_points, seed_total(seeds), sum(len(c.photons) for c in configs)))
    seeds = check_seeds(seeds)
    point_seed = params.seed(point_seed, "point_seed")
    reference = study_reference.Reference() if reference is None else study_reference.parse(reference)
    study_reference.check_available(reference)
    bound_params = dict(bound_params or {})
    unknown = set(bound_params) - {"l_max", "r_max"}
    if unknown:
        raise OclgiError(f"bound_params takes l_max and r_max, not {sorted(unknown)}")
    pts = study_points(engine, points, point_seed)
    pts = _located(engine, pts, need=any(c.method == "impact" for c in configs))
    scene = engine.scene
    radii = [c.radius or scene.radius for c in configs if c.is_detp]
    max_photons = max(p for c in configs for p in c.photons)

    saved, engine.progress = engine.progress, False  # one study-wide bar instead of one per run
    try:
        for c in configs:  # builds programs (untimed) and rejects bad options before the long work
            engine.irradiance(pts, method=c.method, photons=min(WARMUP_PHOTONS, max(c.photons)), radius=c.radius,
                              seed=0, **c.options)
        ref = study_reference.compute(engine, pts, reference, max_photons, min(radii) if radii else None)
        if not trusted(ref).any():
            raise OclgiError(f"the reference ({ref.description}) is known to {REFERENCE_TRUST:.0%} at none of the "
                             f"{len(pts):,} points: use a stronger reference (more photons or samples) or "
                             f"more points")
        albedo = _albedo(scene, pts)
        inputs = study_bounds.scene_inputs(scene, ref.values, _emission(scene, pts), **bound_params)
        total = sum(p for c in configs for p in c.photons) * len(seeds)
        bar = Progress("study", total, progress)
        rows = [_run_row(engine, pts, c, n, seeds, inputs, bar) for c in configs for n in c.photons]
        bar.close()
    finally:
        engine.progress = saved
    result = StudyResult(scene.name, pts, seeds, ref, inputs, albedo, rows)
    for r in rows:
        r.summary = summarise(result, r)
    result.seconds = time.perf_counter() - t_start
    return result


def _run_row(engine, pts, c: Config, photons: int, seeds, inputs, bar) -> Row:
    irr, secs, est_secs, segs = [], [], [], []
    for s in seeds:
        e = engine.irradiance(pts, method=c.method, photons=photons, radius=c.radius, seed=s, **c.options)
        irr.append(e.irradiance.astype(np.float64))
        secs.append(e.stats.seconds["total"])
        est_secs.append(e.stats.seconds["total"] - e.stats.seconds["trace"])
        segs.append(e.stats.segments)
        bar.update(photons)
    radius = (c.radius or engine.scene.radius) if c.is_detp else None
    segments = float(np.mean(segs))
    bound = study_bounds.radiance_bound(inputs, c.method, c.options, radius, photons, pts.tri)
    return Row(c, c.label(engine.scene.radius), photons, radius, np.stack(irr), np.array(secs),
               np.array(est_secs), segments, bound)


def _albedo(scene, pts) -> np.ndarray:
    """Albedo of the triangle under each point (its diffuse part's, which turns
    irradiance into the radiance the study compares); R_max per channel where unknown."""
    albedo = np.array([m.diffuse_albedo for m in scene.materials], np.float64)
    return _under(scene, pts, albedo, albedo[np.unique(scene.tri_material)].max(axis=0))


def _emission(scene, pts) -> np.ndarray:
    return _under(scene, pts, np.array([m.emission for m in scene.materials], np.float64), np.zeros(3))


def _under(scene, pts, per_material: np.ndarray, unknown: np.ndarray) -> np.ndarray:
    """(n, 3): the value of the material under each point, ``unknown`` where no triangle is."""
    out = np.tile(unknown, (len(pts), 1))
    on = pts.tri >= 0
    out[on] = per_material[scene.tri_material[pts.tri[on]]]
    return out


def summarise(result: StudyResult, row: Row) -> dict:
    """The row's summary over the valid points (module docstring)."""
    ref = result.reference.values
    valid = result.valid
    e = row.irradiance
    n_seeds = len(e)
    mean, var = e.mean(axis=0), e.var(axis=0, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_bias = ((mean - ref) / ref)[valid]
        rel_var = (var / ref**2)[valid]
        rel_mse = (((e - ref) ** 2).mean(axis=0) / ref**2)[valid]
        ref_rel_var = ((result.reference.std_error / ref) ** 2)[valid]
        per_seed = ((e - ref) / ref)[:, valid].mean(axis=1)  # mean relative error of each seed's run
    nv = max(int(valid.sum()), 1)
    bias_se = math.sqrt(per_seed.var(ddof=1) / n_seeds + ref_rel_var.mean() / nv) if valid.any() else math.nan
    rms_bias = math.sqrt(max(0.0, float(np.mean(rel_bias**2) - np.mean(rel_var) / n_seeds - ref_rel_var.mean()))) \
        if valid.any() else math.nan
    var_l = (result.albedo / math.pi) ** 2 * var
    has_bound = np.isfinite(row.bound) & (result.albedo > 0)
    ratio = var_l[has_bound] / row.bound[has_bound]
    time_s = float(np.median(row.seconds))
    mean_rel_var = float(np.mean(rel_var)) if valid.any() else math.nan
    if valid.any():
        scale = float(ref[valid].mean())
        nbias = float((mean - ref)[valid].mean()) / scale
        nvar = float(var[valid].mean()) / scale**2
        mse = ((e - ref) ** 2).mean(axis=0)[valid].mean() - (result.reference.std_error**2)[valid].mean()
        nrmse = math.sqrt(max(0.0, float(mse))) / scale
    else:
        nbias = nvar = nrmse = math.nan
    c = row.config
    return {
        "label": row.label,
        "method": c.method,
        "photons": row.photons,
        "radius": row.radius if row.radius is not None else "",
        "k": c.options.get("k", study_bounds.DEFAULT_K) if c.method in KNN_METHODS else "",
        "estimator": c.options.get("estimator", "k-1") if c.method in KNN_METHODS else "",
        "seeds": n_seeds,
        "points": int(valid.any(axis=1).sum()),
        "segments": row.segments,
        "rel_bias": float(np.mean(rel_bias)) if valid.any() else math.nan,
        "rel_bias_se": bias_se,
        "rms_bias": rms_bias,
        "rel_var": mean_rel_var,
        "rel_rmse": float(math.sqrt(max(0.0, np.mean(rel_mse) - ref_rel_var.mean()))) if valid.any() else math.nan,
        "nbias": nbias,
        "nvar": nvar,
        "nrmse": nrmse,
        "time_s": time_s,
        "estimate_s": float(np.median(row.estimate_seconds)),
        "efficiency": 1.0 / (time_s * nvar) if nvar > 0 else math.inf,
        "var_L": float(np.mean(var_l[has_bound])) if has_bound.any() else math.nan,
        "bound": float(np.mean(row.bound[has_bound])) if has_bound.any() else math.nan,
        "bound_ratio_mean": float(np.mean(ratio)) if ratio.size else math.nan,
        "bound_ratio_max": float(np.max(ratio)) if ratio.size else math.nan,
        "under_bound": float(np.mean(ratio <= 1.0)) if ratio.size else math.nan,
    }
