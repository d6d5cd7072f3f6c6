"""DETP acceleration study: does oclgi reproduce the thesis' cost model?

Runs every DETP method on the Cornell box with exact work counters
(``count_work=True``: t segment-sphere tests, u segment-disc tests, BVH node
visits) and wall times, and writes into ``bench/results/``:

- ``detp_study.json``  every measurement (machine, sizes, counts, seconds);
- ``detp_study.md``    the tables that ``bench/HISTORY.md`` quotes;
- ``detp_*.png``       the plots.

Experiments (DESIGN.md section 3):

1. scaling in n_P (query points) and in n_R (segments) for each method, with
   least-squares exponents of time and of counted work, beside the model's
   (plain: n_R n_P; sphere cache and disc indexing: n_R n_P^(1/3));
2. the sphere cache's Q sweep, counted (t + u) and timed, with the model
   curve 1 / (Q^2 (1 - Q)) (least at Q = 2/3) overlaid;
3. disc indexing vs sphere cache for small and large discs, and the unit
   costs of a t test and a u test;
4. the sphere cache with Hilbert, Morton and no ordering, as speedups over
   plain DETP.

Usage: ``.venv/bin/python bench/detp_study.py [--quick]`` (``--quick``
shrinks every size about tenfold, for a smoke run).
"""

from __future__ import annotations

import json
import math
import platform
import time

import numpy as np

from common import RESULTS, arguments, engine, figure, surface_points, write

ACCELERATED = ["detp_sphere_cache", "detp_disc_index", "detp_ray_map"]
MODEL_NP_EXPONENT = {"detp": 1.0, "detp_sphere_cache": 1 / 3, "detp_disc_index": 1 / 3}


def spacing_radius(scene, n_points, fraction=0.25):
    """A disc radius small against the point spacing: disc area = fraction^2 x area per point."""
    return fraction * math.sqrt(scene.triangle_areas().sum() / (math.pi * n_points))


class Study:
    def __init__(self, quick: bool):
        self.s = 0.1 if quick else 1.0  # every size's scale
        self.rng = np.random.default_rng(2026)
        self.engine = engine("cornell_box.toml")
        self.scene = self.engine.scene
        self.rows = []
        self._points = {}

    def points(self, n):
        if n not in self._points:
            self._points[n] = surface_points(self.scene, n, self.rng)
        return self._points[n]

    def run(self, experiment, method, n_points, photons, radius, **options):
        est = self.engine.irradiance(self.points(n_points), method=method, photons=photons, radius=radius,
                                     count_work=True, **options)
        row = {"experiment": experiment, "method": method, "n_P": n_points, "photons": photons,
               "n_R": est.stats.segments, "radius": radius, "options": options,
               "seconds": est.stats.seconds["estimate"], **est.work}
        self.rows.append(row)
        print(f"{experiment:10s} {method:18s} n_P={n_points:>8,} n_R={row['n_R']:>9,} d={radius:.4g} "
              f"{options} t={row['t']:,} u={row['u']:,} {row['seconds']:.3f}s", flush=True)

    # -- experiments ---------------------------------------------------------
    def scaling(self):
        s, photons = self.s, int(200_000 * self.s)
        for method in ["detp"] + ACCELERATED:
            sizes = [1_000, 4_000, 16_000] if method == "detp" else [1_000, 10_000, 100_000, 1_000_000]
            for n_p in [max(200, int(n * s)) for n in sizes]:
                self.run("scale_nP", method, n_p, photons, spacing_radius(self.scene, n_p))
            n_p = max(200, int(10_000 * s))
            counts = [10_000, 50_000, 200_000] if method == "detp" else [10_000, 50_000, 200_000, 500_000]
            for ph in counts:
                self.run("scale_nR", method, n_p, max(1000, int(ph * s)), spacing_radius(self.scene, n_p))

    def q_sweep(self):
        n_p = max(500, int(100_000 * self.s))
        for q in (0.4, 0.5, 0.6, 0.65, 2 / 3, 0.7, 0.75, 0.8, 0.9):
            self.run("q_sweep", "detp_sphere_cache", n_p, int(100_000 * self.s), spacing_radius(self.scene, n_p), q=q)

    def disc_size(self):
        n_p, photons = max(500, int(50_000 * self.s)), int(100_000 * self.s)
        for label, radius in (("small", spacing_radius(self.scene, n_p)), ("large", 0.05 * self.scene.diagonal)):
            for method in ["detp"] + ACCELERATED:
                if method == "detp" and n_p * photons > 2e9:
                    continue
                self.run(f"disc_{label}", method, n_p, photons, radius)

    def ordering(self):
        n_p, photons = max(500, int(20_000 * self.s)), int(50_000 * self.s)
        radius = 0.1 * self.scene.diagonal / 2  # the thesis' test: 10% of the scene radius
        self.run("ordering", "detp", n_p, photons, radius)
        for order in ("hilbert", "morton", "none"):
            self.run("ordering", "detp_sphere_cache", n_p, photons, radius, order=order)


def fit_exponent(x, y):
    x, y = np.log(np.asarray(x, float)), np.log(np.maximum(np.asarray(y, float), 1e-30))
    return float(np.polyfit(x, y, 1)[0])


def summarise(rows):
    md = ["# DETP acceleration study", ""]
    by = lambda exp, m: [r for r in rows if r["experiment"] == exp and r["method"] == m]  # noqa: E731
    methods = sorted({r["method"] for r in rows}, key=lambda m: (m != "detp", m))

    md += ["## Scaling exponents", "",
           "| method | n_P exponent of work (t+u) | of time | model | n_R exponent of work | of time |",
           "|---|---:|---:|---:|---:|---:|"]
    exps = {}
    for m in methods:
        a, b = by("scale_nP", m), by("scale_nR", m)
        if len(a) < 2 or len(b) < 2:
            continue
        of = {"work": lambda r: r["t"] + r["u"], "time": lambda r: r["seconds"]}
        e = exps[m] = {f"n{x}_{y}": fit_exponent([r[f"n_{x}"] for r in rs], [f(r) for r in rs])
                       for x, rs in (("P", a), ("R", b)) for y, f in of.items()}
        model = MODEL_NP_EXPONENT.get(m)
        md.append(f"| {m} | {e['nP_work']:.2f} | {e['nP_time']:.2f} | {model if model is None else f'{model:.2f}'} "
                  f"| {e['nR_work']:.2f} | {e['nR_time']:.2f} |")

    q = by("q_sweep", "detp_sphere_cache")
    if q:
        md += ["", "## Sphere cache: Q sweep", "",
               "| Q | t | u | t + u | seconds | model 1/(Q^2(1-Q)) |", "|---:|---:|---:|---:|---:|---:|"]
        md += [f"| {qq:.3f} | {r['t']:,} | {r['u']:,} | {r['t'] + r['u']:,} | {r['seconds']:.3f} "
               f"| {1 / (qq * qq * (1 - qq)):.2f} |" for r in q for qq in [r["options"]["q"]]]
        md.append(f"\nLeast counted work at Q = {min(q, key=lambda r: r['t'] + r['u'])['options']['q']:.3f}; least "
                  f"time at Q = {min(q, key=lambda r: r['seconds'])['options']['q']:.3f}.")

    for label in ("small", "large"):
        d = [r for r in rows if r["experiment"] == f"disc_{label}"]
        if d:
            md += ["", f"## {label.capitalize()} discs (d = {d[0]['radius']:.4g})", "",
                   "| method | t | u | nodes | seconds |", "|---|---:|---:|---:|---:|"]
            md += [f"| {r['method']} | {r['t']:,} | {r['u']:,} | {r['nodes']:,} | {r['seconds']:.3f} |" for r in d]
            t = {r["method"]: r["seconds"] for r in d}
            if "detp_disc_index" in t and "detp_sphere_cache" in t:
                md.append(f"\nDisc indexing / sphere cache time: {t['detp_disc_index'] / t['detp_sphere_cache']:.2f}")

    plain = [r for r in rows if r["method"] == "detp" and r["u"] > 0]
    if plain:
        c_u = float(np.median([r["seconds"] / r["u"] for r in plain]))
        md += ["", "## Unit costs", "", f"- u (segment-disc test, plain DETP, SIMD lanes): {c_u * 1e9:.3f} ns"]
        sc = [r for r in rows if r["method"] == "detp_sphere_cache" and r["t"] > 0]
        if sc:
            c_t = float(np.median([max(r["seconds"] - c_u * r["u"], 0) / r["t"] for r in sc]))
            md.append(f"- t (segment-sphere test, sphere cache, incl. list rebuilds): {c_t * 1e9:.3f} ns")

    o = [r for r in rows if r["experiment"] == "ordering"]
    if o:
        base = next(r["seconds"] for r in o if r["method"] == "detp")
        md += ["", "## Ordering (speedup over plain DETP)", "", "| method | order | t + u | seconds | speedup |",
               "|---|---|---:|---:|---:|"]
        md += [f"| {r['method']} | {r['options'].get('order', '-')} | {r['t'] + r['u']:,} "
               f"| {r['seconds']:.3f} | {base / r['seconds']:.1f}x |" for r in o]
    return "\n".join(md) + "\n", exps


def plots(rows):
    fig, axes = figure(1, 2, figsize=(11, 4.2))
    for m in sorted({r["method"] for r in rows}):
        a = [r for r in rows if r["experiment"] == "scale_nP" and r["method"] == m]
        if a:
            axes[0].loglog([r["n_P"] for r in a], [r["t"] + r["u"] for r in a], "o-", label=f"{m} work")
            axes[1].loglog([r["n_P"] for r in a], [r["seconds"] for r in a], "o-", label=m)
    axes[0].set(xlabel="n_P", ylabel="counted tests t + u", title="work vs query points")
    axes[1].set(xlabel="n_P", ylabel="seconds", title="time vs query points")
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(RESULTS / "detp_scaling.png", dpi=110)
    out = ["detp_scaling.png"]

    q = [r for r in rows if r["experiment"] == "q_sweep"]
    if q:
        qs = np.array([r["options"]["q"] for r in q])
        work = np.array([r["t"] + r["u"] for r in q], float)
        secs = np.array([r["seconds"] for r in q])
        grid = np.linspace(0.38, 0.92, 200)
        model = 1 / (grid**2 * (1 - grid))
        fig, ax = figure(figsize=(6, 4.2))
        ax.plot(qs, work / work.min(), "o-", label="counted t + u (relative)")
        ax.plot(qs, secs / secs.min(), "s-", label="time (relative)")
        ax.plot(grid, model / model.min(), "k--", label="model 1/(Q^2 (1-Q)) (relative)")
        ax.axvline(2 / 3, color="grey", lw=0.8)
        ax.set(xlabel="Q", ylabel="relative to the least", title="sphere cache: Q sweep")
        ax.legend(fontsize=8)
        ax.grid(True, alpha=0.3)
        fig.tight_layout()
        fig.savefig(RESULTS / "detp_q_sweep.png", dpi=110)
        out.append("detp_q_sweep.png")
    return out


def main():
    args = arguments(__doc__, quick=(False, "about tenfold smaller sizes (smoke run)"),
                     only=dict(nargs="*", help="experiments to run (scaling q_sweep disc_size ordering)"))
    study = Study(args.quick)
    t0 = time.perf_counter()
    for name in args.only or ["scaling", "q_sweep", "disc_size", "ordering"]:
        getattr(study, name)()
    md, exps = summarise(study.rows)
    dev = study.engine.queue.device
    meta = {"machine": platform.processor() or platform.machine(), "device": dev.name.strip(),
            "driver": dev.driver_version, "quick": args.quick, "seconds": time.perf_counter() - t0}
    write("detp_study.json", json.dumps({"meta": meta, "rows": study.rows, "exponents": exps}, indent=1))
    write("detp_study.md", md)
    print(md)
    print("plots:", ", ".join(plots(study.rows)))


if __name__ == "__main__":
    main()
