"""The reference irradiance of an estimator study, with its own error.

Three kinds:

- exact: an (n, 3) or (n,) array, or a callable ``f(positions, normals)``
  returning one (analytic scenes); its error is zero.
- ``detp``: a high-photon DETP run (by default ``detp_disc_index``, which
  equals plain DETP bit for bit, with many more photons and a small disc).
  It is the mean of ``runs`` independent runs, so that its standard error
  comes from their spread (the same photons in total as one run). Its bias
  is DETP's: the mean over a disc of radius d instead of the value at the
  point, second order in d where the irradiance is smooth.
- ``mitsuba``: ``oclgi.study.mitsuba.irradiance(scene, positions,
  normals, spp=..., seed=...)``, an independent path tracer (the ``mitsuba``
  extra); also the mean of ``runs`` runs with distinct seeds.

The reference's seeds are kept apart from the study's (REFERENCE_SEED_BASE):
a run with seed s and n photons is the first n paths of a run with seed s
and more photons, so sharing seeds would correlate them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import OclgiError
from ..params import MAX_PHOTONS

REFERENCE_SEED_BASE = 1 << 40
DEFAULT_RUNS = 4
DEFAULT_SPP = 1024


@dataclass
class Reference:
    """A reference to compute: ``kind`` "detp" or "mitsuba".

    detp: ``photons`` in total over ``runs`` runs (None: the study picks 16x
    its largest count), ``radius`` (None: half the smallest DETP radius of
    the study, else half the scene's), ``method`` the DETP variant.
    mitsuba: ``spp`` samples per point in total over ``runs`` runs.
    """

    kind: str = "detp"
    photons: int | None = None
    radius: float | None = None
    method: str = "detp_disc_index"
    runs: int = DEFAULT_RUNS
    spp: int = DEFAULT_SPP
    seed: int = 0


@dataclass
class ReferenceValues:
    values: np.ndarray  # (n, 3) float64
    std_error: np.ndarray  # (n, 3) standard error of values (zeros when exact)
    description: str
    seconds: float = 0.0


def parse(spec) -> Reference | np.ndarray | object:
    """A reference as the command line writes it: ``detp``, ``detp:PHOTONS``,
    ``mitsuba`` or ``mitsuba:SPP``; anything else is returned unchanged."""
    if not isinstance(spec, str):
        return spec
    kind, _, arg = spec.partition(":")
    if kind not in ("detp", "mitsuba"):
        raise OclgiError(f"unknown reference {spec!r}: use detp[:PHOTONS], mitsuba[:SPP], an array or a callable")
    count = None
    if arg:
        try:
            value = float(arg)
        except ValueError:
            value = float("nan")
        if not (np.isfinite(value) and value.is_integer() and value >= 1):
            raise OclgiError(f"reference {spec!r}: expected a positive integer after ':', got {arg!r}")
        count = int(value)
    if kind == "detp":
        return Reference("detp", photons=count)
    return Reference("mitsuba", spp=count or DEFAULT_SPP)


def check_available(ref) -> None:
    """Fail before any work when the Mitsuba reference cannot run."""
    if isinstance(ref, Reference) and ref.kind == "mitsuba":
        _mitsuba_module().load_mitsuba()  # the mitsuba package itself (an optional extra)


def _mitsuba_module():
    from . import mitsuba as mitsuba_reference

    return mitsuba_reference


def compute(engine, points, ref, max_photons: int, detp_radius: float | None) -> ReferenceValues:
    """The reference at ``points`` (QueryPoints)."""
    n = len(points)
    t0 = time.perf_counter()
    if isinstance(ref, Reference):
        if ref.runs < 2:
            raise OclgiError(f"the reference needs at least 2 runs for its own error, got {ref.runs}")
        if ref.kind == "detp":
            runs, desc = _detp_runs(engine, points, ref, max_photons, detp_radius)
        elif ref.kind == "mitsuba":
            runs, desc = _mitsuba_runs(engine, points, ref)
        else:
            raise OclgiError(f"unknown reference kind {ref.kind!r}")
        values = runs.mean(axis=0)
        se = runs.std(axis=0, ddof=1) / np.sqrt(len(runs))
        return ReferenceValues(values, se, desc, time.perf_counter() - t0)
    if callable(ref):
        values = ref(points.positions[:, :3].astype(np.float64), points.normals[:, :3].astype(np.float64))
        desc = f"exact ({getattr(ref, '__name__', type(ref).__name__)})"
    else:
        values, desc = ref, "exact (given values)"
    values = np.asarray(values, np.float64)
    if values.ndim == 1:
        values = np.repeat(values[:, None], 3, axis=1)
    if values.shape != (n, 3):
        raise OclgiError(f"the reference must give one value or three per point: expected ({n}, 3), "
                         f"got {values.shape}")
    if not np.isfinite(values).all() or (values < 0).any():
        raise OclgiError("the reference irradiance must be finite and >= 0")
    return ReferenceValues(values, np.zeros_like(values), desc, time.perf_counter() - t0)


def _detp_runs(engine, points, ref, max_photons, detp_radius):
    photons = ref.photons or 16 * max_photons
    per_run = max(photons // ref.runs, 1)
    if per_run > MAX_PHOTONS:  # said as the study's numbers, not as the one run's that would refuse it
        given = f"{photons:,} photons" if ref.photons else \
            f"16 times the largest count ({max_photons:,}), {photons:,} photons"
        raise OclgiError(f"the DETP reference would trace {given} in {ref.runs} runs of {per_run:,}, more than "
                         f"a run may trace (2^31): give the reference's count, --reference detp:N, with N at "
                         f"most {ref.runs * MAX_PHOTONS:,}")
    radius = ref.radius or 0.5 * (detp_radius or engine.scene.radius)
    runs = np.stack([
        engine.irradiance(points, method=ref.method, photons=per_run, radius=radius,
                          seed=REFERENCE_SEED_BASE + ref.seed + r).irradiance.astype(np.float64)
        for r in range(ref.runs)])
    desc = (f"{ref.method}, {per_run * ref.runs:,} photons ({ref.runs} runs of {per_run:,}), "
            f"radius {radius:.4g}")
    return runs, desc


def _mitsuba_runs(engine, points, ref):
    module = _mitsuba_module()
    spp = max(ref.spp // ref.runs, 1)
    pos = points.positions[:, :3].astype(np.float64)
    nrm = points.normals[:, :3].astype(np.float64)
    # Mitsuba's randomness is its own: no need to keep clear of the study's seeds
    runs = np.stack([np.asarray(module.irradiance(engine.scene, pos, nrm, spp=spp, seed=ref.seed + r),
                                np.float64)
                     for r in range(ref.runs)])
    if runs.shape[1:] != (len(points), 3):
        raise OclgiError(f"the Mitsuba reference returned shape {runs.shape[1:]}, expected ({len(points)}, 3)")
    return runs, f"Mitsuba, {spp * ref.runs} samples per point ({ref.runs} runs of {spp})"
