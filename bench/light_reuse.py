"""Moving a light by path reuse against recomputing every frame (issue #17).

The Cornell box, its area light off, lit by a point light that goes round
a circle under the ceiling in F frames, F in {4, 16, 64}. Each frame is
estimated at the same query points (floor and walls) by DETP (disc index):

- reuse: ``LightReuse`` with n = N / F paths per position, so every frame
  sums N reused paths (the store, N paths, is traced once for the whole
  animation, plus F shadow rays per stored path for the weights);
- recompute: an ordinary run of N paths per frame with the light there.

Measured per frame: time (reuse: the store's trace and weights spread over
the F frames, plus the frame's connection and estimation; recompute: trace
and estimation) and the relative RMS error against a reference (an
ordinary run of ``REF_FACTOR`` N paths) on ``ERROR_FRAMES`` frames spread
over the animation. At equal path counts the two are compared as
measured; at equal error, recomputation's time is scaled to the path count
that gives reuse's error (error ~ 1/sqrt(paths), time ~ paths).

Models: the thesis -- a reused path costs one connection instead of a whole
path, so the tracing speedup is the mean path length L (segments per
path); Sbert et al. -- each frame gets the samples of the whole animation,
so at equal tracing cost its variance falls by up to F (the positions'
densities overlap fully), an equal-error speedup of up to F.

Two light paths: a circle of radius 0.5 m (positions far apart: their
densities overlap little) and of 0.1 m (a small move, much overlap).
Writes ``bench/results/light_reuse.md``.

Usage: ``.venv/bin/python bench/light_reuse.py [--paths N] [--frames 4,16,64]
[--spans 0.5:detp_disc_index,impact;0.1:detp_disc_index] [--quick]``.
"""

from __future__ import annotations

import time

import numpy as np

import oclgi
from common import RESULTS, ROOT, arguments, figure, timed, write
from oclgi.tracing.light_reuse import LightReuse
from oclgi.tracing.light_reweight import Reweighting

BOX = str(ROOT / "scenes" / "cornell-box" / "CornellBox-Original.obj")
RADIUS = 0.06
MAX_DEPTH = 12
REF_FACTOR = 24
ERROR_FRAMES = 4
ERROR_SEEDS = 3  # independent animations whose errors are averaged (only a few points' values are independent)


def scene(photons: int):
    return oclgi.load_dict({"mesh": [{"path": BOX, "materials": {"light": {"emission": [0, 0, 0]}}}],
                            "point_light": [{"name": "lamp", "position": [0.0, 1.6, 0.0],
                                             "intensity": [1.0, 1.0, 1.0]}],
                            "photons": {"count": photons, "seed": 1, "max_depth": MAX_DEPTH}})


def circle(frames: int, span: float = 0.5) -> np.ndarray:
    """F positions round a circle of radius ``span`` under the ceiling (a little up and down)."""
    a = 2 * np.pi * np.arange(frames) / frames
    return np.stack([span * np.cos(a), 1.6 + 0.4 * span * np.sin(3 * a), span * np.sin(a) - 0.1], axis=1)


def query_points(n: int = 600) -> np.ndarray:
    r = np.random.default_rng(3)
    k = n // 4
    floor = [[x, 0.0, z, 0, 1, 0] for x, z in r.uniform([-0.9, -0.9], [0.9, 0.8], (2 * k, 2))]
    back = [[x, y, -1.04, 0, 0, 1] for x, y in r.uniform([-0.9, 0.1], [0.9, 1.85], (k, 2))]
    right = [[1.0, y, z, -1, 0, 0] for y, z in r.uniform([0.1, -0.9], [1.85, 0.8], (k, 2))]
    return np.array(floor + back + right)


def rel_ms(e, ref) -> float:
    """Mean squared error relative to the mean squared reference value (over the points, channels summed)."""
    e, ref = e.sum(axis=1), ref.sum(axis=1)
    return float(np.mean((e - ref) ** 2) / np.mean(ref) ** 2)


def study(engine, frames: int, paths: int, pts, method: str, span: float, seed: int = 11) -> dict:
    positions = circle(frames, span)
    n = paths // frames
    setup, reuse = timed(LightReuse, engine, "lamp", positions, photons=n, seed=seed, max_depth=MAX_DEPTH)
    est = reuse.estimator(pts, method=method, radius=RADIUS)
    rw_est = rw = None
    if method == "detp_disc_index":  # the tails' stored pairs re-weighted (oclgi/tracing/light_reweight.py)
        rw_est = reuse.estimator(pts, method=method, radius=RADIUS)
        rw = Reweighting(reuse, rw_est)
    err_frames = sorted(set(np.linspace(0, frames - 1, ERROR_FRAMES).round().astype(int).tolist()))
    secs = {k: [] for k in ("connect", "frame", "rw", "direct", "rec")}  # wall seconds, a list per frame

    def clock(key, fn, *args, **kwargs):
        t, out = timed(fn, *args, **kwargs)
        secs[key].append(t)
        return out

    def recompute(photons, seed):
        return engine.irradiance(pts, method=method, photons=photons, radius=RADIUS, seed=seed, max_depth=MAX_DEPTH)

    errs_reuse, errs_rec, rec_trace, refs = [], [], [], {}
    for j in range(frames):
        clock("connect", lambda: [engine.queue.finish() for _ in reuse.batches(j)])
        e = clock("frame", reuse.estimate, j, est)
        if rw is not None:
            e_rw = clock("rw", reuse.estimate, j, rw_est, reweighting=rw)
            assert np.array_equal(e_rw.accumulators, e.accumulators), "a re-weighted frame differs"
        # the direct light alone: what a frame would still estimate if the
        # tails' contributions were kept per point and only re-weighted
        clock("direct", lambda: ([est.accumulate(b) for b in reuse.batches(j, tails=False)], engine.queue.finish()))
        with reuse.light_at(j):
            r = clock("rec", recompute, n * frames, seed + 1)
            rec_trace.append(r.stats.seconds["trace"])
            if j in err_frames:
                ref = refs[j] = recompute(REF_FACTOR * n * frames, seed + 2).irradiance
                errs_reuse.append(rel_ms(e.irradiance, ref))
                errs_rec.append(rel_ms(r.irradiance, ref))
    for k in range(1, ERROR_SEEDS):  # more animations, for the errors alone
        other = LightReuse(engine, "lamp", positions, photons=n, seed=seed + 10 * k, max_depth=MAX_DEPTH)
        for j in err_frames:
            errs_reuse.append(rel_ms(other.estimate(j, est).irradiance, refs[j]))
            with other.light_at(j):
                errs_rec.append(rel_ms(recompute(n * frames, seed + 10 * k + 1).irradiance, refs[j]))
    mean = {k: float(np.mean(v)) if v else float("nan") for k, v in secs.items()}
    # the references' own error (1/REF_FACTOR of a recomputation's squared error) adds: take it out
    ref_ms = float(np.mean(errs_rec)) / REF_FACTOR
    err_reuse, err_rec = (float(np.sqrt(max(np.mean(x) - ref_ms, 1e-30))) for x in (errs_reuse, errs_rec))
    seg_per_path = reuse.segments / reuse.n_paths
    reuse_frame = setup / frames + mean["frame"]  # the store's cost spread over the frames
    reuse_trace = (reuse.seconds["trace"] + reuse.seconds["weights"]) / frames + mean["connect"]
    rec_frame = mean["rec"]
    eq_paths = (err_rec / err_reuse) ** 2  # recomputation's paths for reuse's error, relative to N
    direct_frame = setup / frames + mean["direct"]
    rw_frame = (setup + rw.seconds) / frames + mean["rw"] if rw is not None else float("nan")
    return {"method": method, "span": span, "F": frames, "n": n, "paths": n * frames, "L": seg_per_path,
            "store_trace_s": reuse.seconds["trace"], "weights_s": reuse.seconds["weights"], "setup_s": setup,
            "connect_s": mean["connect"], "reuse_frame_s": reuse_frame, "rec_frame_s": rec_frame,
            "rec_trace_s": float(np.mean(rec_trace)), "err_reuse": err_reuse, "err_rec": err_rec,
            "tracing_speedup": float(np.mean(rec_trace)) / reuse_trace,
            "speedup_equal_paths": rec_frame / reuse_frame,
            "speedup_equal_error": rec_frame * eq_paths / reuse_frame,
            "variance_gain": eq_paths, "direct_frame_s": direct_frame,
            "bound_equal_error": rec_frame * eq_paths / direct_frame,
            "pairs": rw.n_pairs if rw is not None else 0, "pairs_s": rw.seconds if rw is not None else 0.0,
            "rw_frame_s": rw_frame, "rw_equal_error": rec_frame * eq_paths / rw_frame}


def report(rows: list[dict], paths: int, points: int, seconds: float):
    header = ("| method | span m | F | n/pos | L (seg/path) | store trace s | weights s | reuse frame ms | "
              "recompute frame ms | err reuse | err recompute | tracing speedup (model L) | speedup, equal paths | "
              "speedup, equal error (Sbert: up to F) | variance gain | direct-only frame ms | "
              "re-weighting bound, equal error | pairs | re-weighted frame ms | re-weighted, equal error |")
    setting = (f"Cornell box (area light off), a point light circling under the ceiling (radius: span); {points} query points on "
               f"the floor and walls, radius {RADIUS} (DETP), max_depth {MAX_DEPTH}; N = {paths:,} paths per "
               f"frame (reuse: N / F per position); errors: relative RMS against {REF_FACTOR} N paths on "
               f"{ERROR_FRAMES} frames of {ERROR_SEEDS} independent animations (the reference's own error taken "
               f"out). Times per frame; reuse's include "
               f"the store's trace and weights over F. Study took {seconds:.0f}s.")
    notes = ("Tracing speedup: recomputation's trace time per frame over reuse's store trace and weights per frame "
             "plus its connection kernel. Variance gain: recomputation's error over reuse's, squared, at equal "
             "paths (the path count recomputation needs for reuse's error, in units of N). Direct-only frame: the "
             "store's cost per frame plus estimating segment 0 of every path alone; the re-weighting bound is the "
             "equal-error speedup if the tails' contributions cost nothing per frame (an estimator keeping, per "
             "point, the stored tail segments it counts would pay a sparse product over them on top): an upper "
             "bound on what that design can gain. Re-weighted: that design built (oclgi/tracing/light_reweight.py: "
             "the (disc, tail segment) pairs found once, their count in 'pairs', then per frame segment 0 through "
             "the estimator and one pass over the pairs), its frames equal to reuse's bit for bit (asserted), the "
             "pairs' search spread over the F frames like the store's trace.")
    lines = ["# Light reuse against per-frame recomputation (bench/light_reuse.py)", "", setting, "", header,
             "|---" * 20 + "|", *(f"| {r['method']} | {r['span']} | {r['F']} | {r['n']:,} | {r['L']:.2f} | "
                                  f"{r['store_trace_s']:.2f} | {r['weights_s']:.2f} | {r['reuse_frame_s'] * 1e3:.0f} | "
                                  f"{r['rec_frame_s'] * 1e3:.0f} | {r['err_reuse']:.4f} | {r['err_rec']:.4f} | "
                                  f"{r['tracing_speedup']:.2f} ({r['L']:.2f}) | {r['speedup_equal_paths']:.2f} | "
                                  f"{r['speedup_equal_error']:.2f} ({r['F']}) | {r['variance_gain']:.2f} | "
                                  f"{r['direct_frame_s'] * 1e3:.0f} | {r['bound_equal_error']:.2f} | {r['pairs']:,} | "
                                  f"{r['rw_frame_s'] * 1e3:.0f} | {r['rw_equal_error']:.2f} |" for r in rows),
             "", notes, ""]
    return write("light_reuse.md", "\n".join(lines))


def plot(rows: list[dict]):
    """Speedups against F with the models: the tracing part against the
    thesis' L, the whole frame at equal error (plain reuse and re-weighted)
    against Sbert et al.'s bound F."""
    fig, (ax_t, ax_e) = figure(1, 2, figsize=(10, 4))
    fs = sorted({r["F"] for r in rows})
    for key in sorted({(r["method"], r["span"]) for r in rows}):
        sel = [r for r in rows if (r["method"], r["span"]) == key]
        f = [r["F"] for r in sel]
        label = f"{key[0]}, {key[1]} m"
        ax_t.plot(f, [r["tracing_speedup"] for r in sel], "o-", label=label)
        ax_e.plot(f, [r["speedup_equal_error"] for r in sel], "o-", label=f"{label}: reuse")
        if sel[0]["pairs"]:
            ax_e.plot(f, [r["rw_equal_error"] for r in sel], "s--", label=f"{label}: re-weighted")
    mean_l = float(np.mean([r["L"] for r in rows]))
    ax_t.axhline(mean_l, color="k", ls=":", label=f"thesis: L = {mean_l:.2f}")
    ax_e.plot(fs, fs, "k:", label="Sbert et al.: up to F")
    ax_e.axhline(2.0, color="grey", ls="--", lw=0.8, label="goal: 2x")
    for ax, title in ((ax_t, "tracing speedup"), (ax_e, "frame speedup at equal error")):
        ax.set_xscale("log", base=2)
        ax.set(xlabel="frames F", title=title)
        ax.legend(fontsize=7)
    ax_e.set_yscale("log", base=2)
    fig.savefig(out := RESULTS / "light_reuse.png", dpi=110, bbox_inches="tight")
    return out


def main():
    args = arguments(__doc__, paths=(64_000, "paths per frame, N (default 64000)"),
                     frames=("4,16,64", "frame counts F (default 4,16,64)"),
                     spans=("0.5:detp_disc_index,impact;0.1:detp_disc_index", "the light path's radii (m), each "
                            "with its methods (default 0.5:detp_disc_index,impact;0.1:detp_disc_index)"),
                     quick=dict(paths=8000, frames="4,16"))
    paths, frames = args.paths, [int(f) for f in args.frames.split(",")]
    spans = [(float(a), b.split(",")) for a, b in (part.split(":") for part in args.spans.split(";"))]
    t0 = time.perf_counter()
    engine = oclgi.Engine(scene(paths))
    pts = query_points()
    engine.irradiance(pts, photons=1000, radius=RADIUS)  # kernels compiled before any timing
    warm = LightReuse(engine, "lamp", circle(2), photons=100)
    for method in sorted({m for _, ms in spans for m in ms}):
        warm.estimate(0, warm.estimator(pts, method=method, radius=RADIUS))
        engine.irradiance(pts, method=method, photons=1000, radius=RADIUS)
    rw_est = warm.estimator(pts, method="detp_disc_index", radius=RADIUS)
    warm.estimate(0, rw_est, reweighting=Reweighting(warm, rw_est))  # its kernels built before any timing
    rows = []
    for span, methods in spans:
        for method in methods:
            for f in frames:
                rows.append(study(engine, f, paths, pts, method, span))
                print({k: round(v, 4) if isinstance(v, float) else v for k, v in rows[-1].items()}, flush=True)
    print(f"wrote {report(rows, paths, len(pts), time.perf_counter() - t0)} and {plot(rows)}")


if __name__ == "__main__":
    main()
