"""Statistics over a study's rows that the report and the command share:
the reference's trust level and each configuration's error at equal time.

Kept apart from ``run.py`` so that the report can use them without
importing the runner (the runner imports the report lazily to write).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import OclgiError

REFERENCE_TRUST = 0.1  # largest relative standard error of the reference at a point the statistics use


@dataclass
class EqualTime:
    time_s: float
    mode: str
    baseline: str
    rows: list  # dicts: label, error, how, ratio (to the baseline), efficiency
    metric: str = "nrmse"


def equal_time(result, time_s: float | None = None, mode: str = "interpolate",
               baseline: str | None = None, metric: str = "nrmse") -> EqualTime:
    """Each configuration's error (``metric``: "nrmse", the default, or
    "rel_rmse") at one common time.

    ``mode="interpolate"``: log-log linear between the two measured points
    around ``time_s``; outside a configuration's measured range, extrapolated
    from its nearest point along RMSE ~ t^(-1/2) (variance-dominated error at
    a fixed cost per photon). ``mode="fit"``: RMSE = c t^(-1/2) fitted to all
    its points (least squares in log). ``time_s`` defaults to the geometric
    middle of the range where all configurations were measured, else of all
    times. ``baseline`` (default: the first DETP configuration, else the
    first) gives the ratio column.
    """
    if mode not in ("interpolate", "fit"):
        raise OclgiError(f"equal_time mode must be 'interpolate' or 'fit', got {mode!r}")
    if metric not in ("nrmse", "rel_rmse"):
        raise OclgiError(f"equal_time metric must be 'nrmse' or 'rel_rmse', got {metric!r}")
    fam = result.families()
    curves = {}
    for label, rows in fam.items():
        t = np.array([r.summary["time_s"] for r in rows])
        e = np.array([r.summary[metric] for r in rows])
        order = np.argsort(t)
        curves[label] = (t[order], e[order], [rows[i] for i in order])
    if time_s is None:
        lo = max(c[0][0] for c in curves.values())
        hi = min(c[0][-1] for c in curves.values())
        if lo > hi:
            ts = np.concatenate([c[0] for c in curves.values()])
            lo, hi = ts.min(), ts.max()
        time_s = float(math.sqrt(lo * hi))
    if baseline is None:
        detp = [lbl for lbl, rows in fam.items() if rows[0].config.is_detp]
        baseline = detp[0] if detp else next(iter(fam))
    out = []
    for label, (t, e, rows) in curves.items():
        value, how = _at_time(t, e, time_s, mode)
        eff = float(np.median([r.summary["efficiency"] for r in rows]))
        out.append({"label": label, "error": value, "how": how, "efficiency": eff})
    base = next(r["error"] for r in out if r["label"] == baseline)
    for r in out:
        r["ratio"] = r["error"] / base if base > 0 else math.nan
    return EqualTime(time_s, mode, baseline, out, metric)


def _at_time(t, e, t0, mode):
    if mode == "fit":
        c = math.exp(float(np.mean(np.log(e) + 0.5 * np.log(t))))
        return c * t0 ** -0.5, "fit c t^-1/2"
    if t0 <= t[0] or t0 >= t[-1] or len(t) == 1:
        i = 0 if t0 <= t[0] else len(t) - 1
        if math.isclose(t0, t[i], rel_tol=1e-9):
            return float(e[i]), "measured"
        return float(e[i] * (t0 / t[i]) ** -0.5), "extrapolated t^-1/2"
    j = int(np.searchsorted(t, t0))
    w = (math.log(t0) - math.log(t[j - 1])) / (math.log(t[j]) - math.log(t[j - 1]))
    return float(math.exp((1 - w) * math.log(e[j - 1]) + w * math.log(e[j]))), "interpolated"
