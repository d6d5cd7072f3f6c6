"""Incremental update study: speedup of an update over recomputation vs f.

García 2007 predicts, for an object of radius r_D = f r_0 moving in a scene
of radius r_0, n_Rec = n_R f^2 recomputed segments and a speedup over
recomputing from scratch of

    S(f) = cbrt(1 + f^3) / (2 f^2 + 8.08 f^3)

(166 at f = 0.05, 6.93 at 0.2, break-even near 0.43). This script measures,
for a ball moving inside a closed room (the furnace scene of
tests/test_update_counts.py, lit uniformly so that the model's assumptions
hold), per f:

- counts: the recomputed segments n_Rec / n_R (model f^2) and, with the
  estimator's work counters, the counted work of an update vs a full run;
- time: a camera session's median update time vs a full recomputation;
- the interactive rate on the Cornell box with the bunny (``--interactive``):
  updates per second with the time split per stage, and the process' memory
  over many frames.

Writes ``bench/results/update_study.{json,md}`` and ``update_speedup.png``.
Usage: ``.venv/bin/python bench/update_study.py [--method M] [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import time
from pathlib import Path

import numpy as np
import trimesh

import oclgi
from oclgi.estimators import METHODS

RESULTS = Path(__file__).resolve().parent / "results"
R0 = math.sqrt(3.0)


def model_speedup(f):
    f = np.asarray(f, float)
    return np.cbrt(1 + f**3) / (2 * f**2 + 8.08 * f**3)


def room_engine(f, photons, width):
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    tri = v[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = np.einsum("ij,ij->i", n, tri.mean(axis=1)) > 0
    faces[out] = faces[out][:, ::-1]
    ball = trimesh.creation.icosphere(subdivisions=4)
    scene = oclgi.load_dict({
        "mesh": [
            {"vertices": v, "faces": faces, "albedo": [0.5] * 3, "emission": [1, 1, 1]},
            {"vertices": ball.vertices * f * R0, "faces": ball.faces, "movable": True, "name": "ball",
             "albedo": [0.5] * 3},
        ],
        "camera": {"position": [0, 0, 0.999], "look_at": [0, 0, 0], "fov": 90, "width": width, "height": width},
        "photons": {"count": photons, "seed": 3, "max_depth": 12},
    })
    return oclgi.Engine(scene, progress=False)


def random_pose(rng, f):
    """A translation keeping the ball inside the room, in front of the camera."""
    r = f * R0
    m = np.eye(4)
    m[:3, 3] = rng.uniform(-1 + r + 0.01, 1 - r - 0.01, 3) * np.array([1, 1, 0.5]) - [0, 0, 0.3 * (1 - r)]
    return m


def speedup_vs_f(method, quick, rng):
    rows = []
    photons = 20_000 if quick else 200_000
    width = 48 if quick else 128
    for f in (0.05, 0.1, 0.15, 0.2, 0.3, 0.4):
        engine = room_engine(f, photons, width)
        t0 = time.perf_counter()
        session = oclgi.Session(engine, method=method, radius=0.02, count_work=True)
        full_s = session.setup_seconds
        full_work = session.estimator.work()
        n_r = int(session.segments()[1].sum())
        upd, rec, pts = [], [], []
        for _ in range(3 if quick else 8):
            before = session.estimator.work()
            st = session.move("ball", random_pose(rng, f))
            after = session.estimator.work()
            upd.append((st.seconds["total"], {k: after[k] - before[k] for k in after}))
            rec.append(st.segments_removed + st.segments_added)
            pts.append(st.points)
        secs = float(np.median([u[0] for u in upd]))
        work = {k: float(np.median([u[1][k] for u in upd])) for k in upd[0][1]}
        rows.append({
            "f": f, "n_R": n_r, "n_Rec_over_n_R": float(np.median(rec)) / 2 / n_r,
            "dynamic_points": float(np.median(pts)), "points": width * width,
            "full_seconds": full_s, "update_seconds": secs, "speedup_time": full_s / secs,
            "full_work": full_work, "update_work": work,
            "speedup_work": (full_work["t"] + full_work["u"]) / max(work["t"] + work["u"], 1),
            "model": float(model_speedup(f)), "wall": time.perf_counter() - t0,
        })
        r = rows[-1]
        print(f"f={f:.2f} n_Rec/n_R={r['n_Rec_over_n_R']:.4f} (f^2={f * f:.4f}) dynamic={r['dynamic_points']:.0f} "
              f"S_time={r['speedup_time']:.2f} S_work={r['speedup_work']:.2f} model={r['model']:.2f}", flush=True)
    return rows


def interactive(method, quick, frames):
    scene = oclgi.load_file(oclgi.scene_path("cornell_bunny.toml"))
    side = 100 if quick else 316  # 10^5 query points
    scene.camera.width = scene.camera.height = side
    engine = oclgi.Engine(scene, progress=False)
    photons = 30_000 if quick else 330_000  # about 10^6 stored segments
    session = oclgi.Session(engine, method=method, photons=photons, radius=0.03)
    n_r = int(session.segments()[1].sum())
    poses = [np.eye(4)] + [None] * frames
    rss = []
    stages = {}
    totals = []
    for i in range(frames):
        m = np.eye(4)
        a = 2 * math.pi * i / max(frames, 1)
        m[:3, 3] = [0.25 * (math.cos(a) - 1), 0, 0.25 * math.sin(a)]
        st = session.move("bunny", m)
        totals.append(st.seconds["total"])
        for k, v in st.seconds.items():
            stages.setdefault(k, []).append(v)
        if i % max(frames // 20, 1) == 0:
            rss.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    del poses
    med = float(np.median(totals))
    return {"n_R": n_r, "points": side * side, "frames": frames, "median_update_s": med,
            "updates_per_s": 1 / med, "stage_median_s": {k: float(np.median(v)) for k, v in stages.items()},
            "max_rss_mib_samples": rss}


def write(rows, inter, method, quick):
    md = [f"# Incremental update study ({method})", "",
          "| f | n_Rec/n_R | f^2 | dynamic points | full s | update s | S (time) | S (work) | model S(f) |",
          "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        md.append(f"| {r['f']:.2f} | {r['n_Rec_over_n_R']:.4f} | {r['f'] ** 2:.4f} | {r['dynamic_points']:.0f} "
                  f"| {r['full_seconds']:.3f} | {r['update_seconds']:.4f} | {r['speedup_time']:.1f} "
                  f"| {r['speedup_work']:.1f} | {r['model']:.1f} |")
    if inter:
        md += ["", "## Interactive rate (Cornell box + bunny)", "",
               f"{inter['n_R']:,} stored segments, {inter['points']:,} query points, {inter['frames']} frames: "
               f"median update {inter['median_update_s'] * 1e3:.1f} ms = **{inter['updates_per_s']:.1f} updates/s**.",
               "", "| stage | median ms |", "|---|---:|"]
        md += [f"| {k} | {v * 1e3:.2f} |" for k, v in inter["stage_median_s"].items()]
        md.append(f"\nPeak RSS over the run (MiB, sampled): {', '.join(f'{x:.0f}' for x in inter['max_rss_mib_samples'])}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "update_study.md").write_text("\n".join(md) + "\n")
    (RESULTS / "update_study.json").write_text(json.dumps({"method": method, "quick": quick, "rows": rows,
                                                           "interactive": inter}, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    fs = np.linspace(0.04, 0.45, 200)
    ax.semilogy(fs, model_speedup(fs), "k--", label="model S(f)")
    ax.semilogy([r["f"] for r in rows], [r["speedup_time"] for r in rows], "o-", label="measured, time")
    ax.semilogy([r["f"] for r in rows], [r["speedup_work"] for r in rows], "s-", label="measured, counted work")
    ax.axhline(1, color="grey", lw=0.8)
    ax.set(xlabel="f = r_D / r_0", ylabel="speedup over recomputation", title=f"incremental update ({method})")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(RESULTS / "update_speedup.png", dpi=110)
    print("\n".join(md))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="detp_disc_index" if "detp_disc_index" in METHODS else "detp")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--interactive", type=int, default=0, metavar="FRAMES",
                    help="also run the interactive-rate benchmark for this many frames")
    args = ap.parse_args()
    rng = np.random.default_rng(7)
    rows = speedup_vs_f(args.method, args.quick, rng)
    inter = interactive(args.method, args.quick, args.interactive) if args.interactive else None
    write(rows, inter, args.method, args.quick)


if __name__ == "__main__":
    main()
