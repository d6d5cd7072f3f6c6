"""Writing an estimator study: a markdown report, a CSV table (one row per
configuration and photon count), a JSON form, and two log-log plots
(relative RMSE against time; variance of L_hat against photons, with each
configuration's bound as a dashed line of the same colour).

matplotlib is imported only when plotting; figures are drawn on their own
``Figure`` with an Agg canvas, so the user's pyplot backend and figures
(a notebook's inline plots) are left alone.
Files are written all or nothing (oclgi/io.py).
"""

from __future__ import annotations

import io as _io
import math
from pathlib import Path

import numpy as np

from ..errors import OclgiError

COLUMNS = ["label", "method", "photons", "radius", "k", "estimator", "seeds", "points", "segments",
           "rel_bias", "rel_bias_se", "rms_bias", "rel_var", "rel_rmse", "nbias", "nvar", "nrmse", "time_s", "estimate_s",
           "efficiency", "var_L", "bound", "bound_ratio_mean", "bound_ratio_max", "under_bound"]

PLOTS = ("error_vs_time.png", "variance_vs_photons.png")


HTML_COLUMNS = ["label", "photons", "seeds", "points", "rel_bias", "rel_var", "nrmse", "time_s", "efficiency",
                "bound_ratio_max"]


def html_table(result) -> str:
    """The study's main columns as an HTML table (a notebook shows it inline)."""
    import html

    head = "".join(f"<th>{c}</th>" for c in HTML_COLUMNS)
    rows = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(r.summary.get(c, '')))}</td>" for c in HTML_COLUMNS)
                   + "</tr>" for r in result.rows)
    return (f"<p>{html.escape(result.scene_name)}: {len(result.rows)} configurations x {len(result.seeds)} seeds at "
            f"{len(result.points):,} points</p><table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>")


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(v):
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
        return f"{v:.6g}"
    return str(v)


def csv_text(result) -> str:
    out = _io.StringIO()
    out.write(",".join(COLUMNS) + "\n")
    for row in result.table():
        out.write(",".join(_csv_field(_fmt(row[c])) for c in COLUMNS) + "\n")
    return out.getvalue()


def _csv_field(text: str) -> str:
    return f'"{text}"' if any(ch in text for ch in ',"\n') else text


def _md_num(v, digits=3) -> str:
    if isinstance(v, str):
        return v
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "n/a"
    if isinstance(v, (int, np.integer)):
        return f"{v:,}"
    if v == 0 or 1e-3 <= abs(v) < 1e5:
        return f"{v:.{digits}g}"
    return f"{v:.{digits - 1}e}"


def _pct(v) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:+.2f}%"


def markdown(result, equal=None) -> str:
    from .stats import REFERENCE_TRUST, equal_time

    equal = equal or equal_time(result)
    ref = result.reference
    valid = result.valid
    with np.errstate(divide="ignore", invalid="ignore"):
        ref_rel = (ref.std_error / ref.values)[valid]
    ref_err = float(np.sqrt(np.mean(ref_rel**2))) if ref_rel.size else math.nan
    lines = [
        f"# Estimator study: {result.scene_name}",
        "",
        f"- points: {len(result.points):,} ({result.points.kind}), {int(valid.any(axis=1).sum()):,} with a "
        f"positive reference known to {100 * REFERENCE_TRUST:.0f}% (the others are left out of the relative "
        f"statistics)",
        f"- seeds: {len(result.seeds)} ({', '.join(map(str, result.seeds[:8]))}{', ...' if len(result.seeds) > 8 else ''})",
        f"- reference: {ref.description}; its relative standard error {_md_num(ref_err)} (RMS over the "
        f"points), computed in {ref.seconds:.1f} s",
        f"- bound inputs: {result.inputs.describe()} (oclgi/study/bound_inputs.py)",
        f"- study time: {result.seconds:.1f} s",
        "",
        "| configuration | photons | rel. bias (± s.e.) | RMS bias | rel. variance | rel. RMSE | nbias | nvar "
        "| nRMSE | time s | estimate s | efficiency 1/s | Var(L̂) | bound | Var/bound mean | max | under bound |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result.table():
        lines.append(
            f"| {r['label']} | {r['photons']:,} | {_pct(r['rel_bias'])} ± {100 * r['rel_bias_se']:.2f}% "
            f"| {_pct(r['rms_bias'])} | {_md_num(r['rel_var'])} | {_md_num(r['rel_rmse'])} "
            f"| {_pct(r['nbias'])} | {_md_num(r['nvar'])} | {_md_num(r['nrmse'])} "
            f"| {_md_num(r['time_s'])} | {_md_num(r['estimate_s'])} | {_md_num(r['efficiency'])} "
            f"| {_md_num(r['var_L'])} | {_md_num(r['bound'])} | {_md_num(r['bound_ratio_mean'])} "
            f"| {_md_num(r['bound_ratio_max'])} | {_md_num(r['under_bound'])} |")
    lines += [
        "",
        f"## Equal time: {_md_num(equal.time_s)} s per run ({equal.metric}, {equal.mode}; ratio to "
        f"{equal.baseline})",
        "",
        f"| configuration | {equal.metric} | ratio | efficiency 1/s (median) | how |",
        "|---|---:|---:|---:|---|",
    ]
    for r in equal.rows:
        lines.append(f"| {r['label']} | {_md_num(r['error'])} | {_md_num(r['ratio'])} "
                     f"| {_md_num(r['efficiency'])} | {r['how']} |")
    lines += [
        "",
        "Columns: relative statistics (means over the points and channels of bias / ref, var / ref^2, MSE / "
        "ref^2) where the reference is positive and known to 10%; the bias's standard error comes from the "
        "per-seed means and the reference's error; the RMS bias has the noise removed; nbias, nvar, nRMSE: "
        "the absolute means over the same points over the mean reference (or its square), which dim points "
        "cannot dominate; efficiency = 1 / (time x nvar); Var(L̂) = (albedo/pi)^2 Var(Ê) against the thesis' "
        "bound, per point (see the docstrings of oclgi/study/run.py and oclgi/study/bound_inputs.py).",
        "",
    ]
    return "\n".join(lines)


def json_dict(result) -> dict:
    from .stats import equal_time

    eq = equal_time(result)
    return {
        "scene": result.scene_name,
        "points": len(result.points),
        "points_kind": result.points.kind,
        "seeds": list(result.seeds),
        "reference": result.reference.description,
        "bound_inputs": result.inputs.describe(),
        "seconds": result.seconds,
        "rows": [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()}
                 for r in result.table()],
        "equal_time": {"time_s": eq.time_s, "mode": eq.mode, "metric": eq.metric, "baseline": eq.baseline,
                       "rows": eq.rows},
    }


# -- plots ---------------------------------------------------------------------------


def _figure():
    """A figure of its own, outside pyplot's state."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise OclgiError("plots need matplotlib (pip install oclgi[study])") from None
    fig = Figure(figsize=(6.4, 4.6))
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot()


def _loglog(x, y):
    """The points of a curve a log-log plot can show (finite, positive)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    return x[keep], y[keep]


def plot_error_vs_time(result, path) -> None:
    fig, ax = _figure()
    for label, rows in result.families().items():
        t, e = _loglog([r.summary["time_s"] for r in rows], [r.summary["nrmse"] for r in rows])
        if len(t):
            ax.plot(t, e, "o-", label=label)
    _finish(fig, ax, "time per run (s, median over seeds)", "RMSE / mean reference",
            f"{result.scene_name}: error vs time", path)


def plot_variance_vs_photons(result, path) -> None:
    fig, ax = _figure()
    for i, (label, rows) in enumerate(result.families().items()):
        color = f"C{i % 10}"
        n = [r.photons for r in rows]
        for key, style, kw in (("var_L", "o-", {"label": label}), ("bound", "--", {"alpha": 0.7})):
            x, y = _loglog(n, [r.summary[key] for r in rows])
            if len(x):
                ax.plot(x, y, style, color=color, **kw)
    _finish(fig, ax, "photon paths", "Var(L̂) (mean over points); dashed: bound",
            f"{result.scene_name}: variance vs photons", path)


def _finish(fig, ax, xlabel, ylabel, title, path) -> None:
    if ax.has_data():  # log scales only with data to scale (an empty log axis raises)
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=110)


# -- all files ----------------------------------------------------------------------------


def write_all(result, out_dir, stem: str = "study", plots: bool = True, prefix: str = "") -> list:
    """``stem.md``, ``stem.csv`` and the plots (``prefix`` + their names) in
    ``out_dir``, each under a temporary name until all are complete."""
    from ..io import atomic_paths, check_output

    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OclgiError(f"{out_dir}: exists and is not a folder")
    texts = {out_dir / f"{stem}.md": result.to_markdown(), out_dir / f"{stem}.csv": result.to_csv()}
    figures = {}
    if plots:
        figures = {out_dir / f"{prefix}{PLOTS[0]}": plot_error_vs_time,
                   out_dir / f"{prefix}{PLOTS[1]}": plot_variance_vs_photons}
    paths = [*texts, *figures]
    for p in paths:
        check_output(p)
    created = not out_dir.exists()
    try:
        # Every file is flushed and checked before any is renamed into place.
        with atomic_paths(paths) as temps:
            tmp = dict(zip(paths, temps))
            for p, text in texts.items():
                tmp[p].write_text(text)
            for p, plot in figures.items():
                plot(result, tmp[p])
    except BaseException:
        if created and out_dir.is_dir() and not any(out_dir.iterdir()):
            out_dir.rmdir()  # nothing was written: leave no empty folder either
        raise
    return paths
