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
- the static points' constants: counted work of an update per changed
  segment, disc indexing vs the sphere cache (the model's 2 vs 8.08);
- the dynamic points (pixels on the moving object): disc indexing over
  the paths near their discs after the update (the default), folded into
  the find pass, over the whole store, the sphere cache;
- the interactive rate on the Cornell box and on Sponza, each with the
  Stanford bunny (f = 0.1) going round: updates per second with the time
  split per stage, and the process' memory over the frames; and the rate
  against the number of stored segments (``segments``);
- final gathering in a session (``gather``): the Cornell box + bunny going
  round, sensor points on the floor and walls, exact direct light with
  and without N gather rays: the update's stages (``gather``: the rays
  traced again and the changed discs summed over the store) and the read
  (resolve: the direct light of the points and of their hits).

Writes ``bench/results/update_study.{json,md}`` and ``update_speedup.png``.
Usage: ``.venv/bin/python bench/update_study.py [--parts speedup,constants,
dynamic,interactive,segments,gather] [--frames N] [--scenes cornell,sponza] [--quick]``.
"""

from __future__ import annotations

import json
import math
import resource
import time

import numpy as np
import trimesh

import oclgi
from common import RESULTS, arguments, box, engine as make_engine, figure, write

R0 = math.sqrt(3.0)


def model_speedup(f):
    f = np.asarray(f, float)
    return np.cbrt(1 + f**3) / (2 * f**2 + 8.08 * f**3)


def room_engine(f, photons, width):
    v, faces = box((-1, -1, -1), (1, 1, 1))  # wound outwards: reversed, the walls face (and emit) into the room
    ball = trimesh.creation.icosphere(subdivisions=4)
    return make_engine({
        "mesh": [
            {"vertices": v, "faces": faces[:, ::-1], "albedo": [0.5] * 3, "emission": [1, 1, 1]},
            {"vertices": ball.vertices * f * R0, "faces": ball.faces, "movable": True, "name": "ball",
             "albedo": [0.5] * 3},
        ],
        "camera": {"position": [0, 0, 0.999], "look_at": [0, 0, 0], "fov": 90, "width": width, "height": width},
        "photons": {"count": photons, "seed": 3, "max_depth": 12},
    })


def random_pose(rng, f):
    """A translation keeping the ball inside the room, in front of the camera."""
    r = f * R0
    m = np.eye(4)
    m[:3, 3] = rng.uniform(-1 + r + 0.01, 1 - r - 0.01, 3) * np.array([1, 1, 0.5]) - [0, 0, 0.3 * (1 - r)]
    return m


def speedup_vs_f(method, quick, rng):
    rows = []
    photons, width = (20_000, 48) if quick else (200_000, 128)
    for f in (0.05, 0.1, 0.15, 0.2, 0.3, 0.4):
        engine = room_engine(f, photons, width)
        t0 = time.perf_counter()
        session = oclgi.Session(engine, method=method, radius=0.02, count_work=True)
        full_s, full_work = session.setup_seconds, session.estimator.work()
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
        rows.append(r := {
            "f": f, "n_R": n_r, "n_Rec_over_n_R": float(np.median(rec)) / 2 / n_r,
            "dynamic_points": float(np.median(pts)), "points": width * width,
            "full_seconds": full_s, "update_seconds": secs, "speedup_time": full_s / secs,
            "full_work": full_work, "update_work": work,
            "speedup_work": (full_work["t"] + full_work["u"]) / max(work["t"] + work["u"], 1),
            "model": float(model_speedup(f)), "wall": time.perf_counter() - t0})
        print(f"f={f:.2f} n_Rec/n_R={r['n_Rec_over_n_R']:.4f} (f^2={f * f:.4f}) dynamic={r['dynamic_points']:.0f} "
              f"S_time={r['speedup_time']:.2f} S_work={r['speedup_work']:.2f} model={r['model']:.2f}", flush=True)
    return rows


def _box_radius(vertices):
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return 0.5 * float(np.linalg.norm(hi - lo)), lo, hi


def scaled_pose(scene, name, f, base, offset=(0.0, 0.0, 0.0)):
    """World-from-loaded matrix that scales object ``name`` to radius
    f r_0 (r_0: half the diagonal of the static geometry) and stands it with
    the centre of its base at ``base + offset``."""
    static = scene.tri_object != scene.object_id(name)
    r0, _, _ = _box_radius(scene.vertices[scene.faces[static]].reshape(-1, 3))
    rd, lo, hi = _box_radius(scene.vertices[scene.faces[~static]].reshape(-1, 3))
    s = f * r0 / rd
    foot = np.array([(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2])
    m = np.eye(4)
    m[:3, :3] *= s
    m[:3, 3] = np.asarray(base, float) + np.asarray(offset, float) - s * foot
    return m


BUNNY = {"path": "stanford-bunny/bun_zipper.ply", "name": "bunny", "movable": True, "albedo": [0.8, 0.8, 0.8]}
SCENES = {
    # name: (scene dict, where the bunny stands, radius of its circular path)
    "cornell": ({
        "mesh": [{"path": "cornell-box/CornellBox-Original.obj"}, BUNNY],
        "camera": {"position": [0.0, 1.0, 3.94], "look_at": [0.0, 1.0, 0.0], "fov": 39.3},
        "photons": {"seed": 1, "max_depth": 12},
    }, [-0.3, 0.0, 0.3], 0.25),
    "sponza": ({
        "mesh": [{"path": "sponza-dabrovic/sponza.zip", "albedo": [0.7, 0.7, 0.7]}, BUNNY],
        "point_light": [{"position": [0.0, 6.0, 0.0], "intensity": [50.0, 50.0, 50.0]}],
        "camera": {"position": [-11.0, 4.0, 0.0], "look_at": [0.0, 2.0, 0.0], "fov": 60.0},
        "photons": {"seed": 1, "max_depth": 12},
    }, [0.0, 0.0, 0.0], 3.0),
}


def scene_engine(name, side):
    data, base, path_r = SCENES[name]
    data = json.loads(json.dumps(data))
    data["camera"].update(width=side, height=side)
    return make_engine(data), base, path_r


def photons_for(engine, segments):
    """Photon paths giving about ``segments`` stored segments."""
    _, lens = engine.trace(photons=20_000)
    return int(segments / lens.mean())


def circle(scene, f, base, path_r, frames, i):
    a = 2 * math.pi * i / max(frames, 1)
    return scaled_pose(scene, "bunny", f, base, (path_r * (math.cos(a) - 1), 0.0, path_r * math.sin(a)))


def interactive(name, method, quick, frames, f=0.1, dynamic="detp_disc_index", segments=1e6):
    """Updates per second: a camera session (10^5 pixels), 10^6 stored
    segments, the bunny (f = 0.1) going round a circle; stages and memory."""
    side = 100 if quick else 316  # 10^5 query points
    engine, base, path_r = scene_engine(name, side)
    engine.move("bunny", circle(engine.scene, f, base, path_r, frames, 0))
    photons = photons_for(engine, segments / 10 if quick else segments)
    session = oclgi.Session(engine, method=method, photons=photons, radius=0.03 if name == "cornell" else 0.3,
                            dynamic=dynamic)
    n_r = int(session.segments()[1].sum())
    rss, stats = [], []
    # the poses first, as a user interface hands them over: finding the
    # bunny's scale reads every vertex of the scene (milliseconds in Sponza)
    poses = [circle(engine.scene, f, base, path_r, frames, i) for i in range(frames + 1)]
    for i in range(1, frames + 1):
        stats.append(session.move("bunny", poses[i]))
        if i % max(frames // 20, 1) == 0:
            rss.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    med = float(np.median([st.seconds["total"] for st in stats]))
    stages = {k: float(np.median([st.seconds[k] for st in stats if k in st.seconds]))
              for k in dict.fromkeys(k for st in stats for k in st.seconds)}
    return {"scene": name, "f": f, "dynamic": dynamic, "n_R": n_r, "photons": photons, "points": side * side,
            "frames": frames, "median_update_s": med, "updates_per_s": 1 / med,
            "dynamic_points_median": float(np.median([st.points for st in stats])),
            "paths_median": float(np.median([st.paths for st in stats])), "stage_median_s": stages,
            "max_rss_mib_samples": rss, "setup_s": session.setup_seconds}


def gather_session(quick, frames, n_points=1000, rays=(0, 16, 64), segments=1e6):
    """A session over sensor points (floor and walls of the Cornell box) with
    exact direct light and N gather rays, the bunny (f = 0.1) going round:
    median ms per stage of a move, of the read (irradiance()), the rays a
    move changed."""
    engine, base, path_r = scene_engine("cornell", 8)
    rng = np.random.default_rng(3)
    n = n_points // 2
    floor = np.column_stack([rng.uniform(-0.95, 0.95, n), np.zeros(n), rng.uniform(-0.95, 0.95, n),
                             np.zeros(n), np.ones(n), np.zeros(n)])
    wall = np.column_stack([rng.uniform(-0.95, 0.95, n), rng.uniform(0.05, 1.9, n), np.full(n, -1.0),
                            np.zeros(n), np.zeros(n), np.ones(n)])
    pts = np.concatenate([floor, wall])
    engine.move("bunny", circle(engine.scene, 0.1, base, path_r, frames, 0))
    photons = photons_for(engine, segments / 10 if quick else segments)
    poses = [circle(engine.scene, 0.1, base, path_r, frames, i) for i in range(frames + 1)]
    rows = []
    for n_rays in rays:
        kw = dict(method="detp_disc_index", photons=photons, radius=0.03, direct="exact")
        if n_rays:
            kw["gather"] = n_rays
        with oclgi.Session(engine, pts, **kw) as s:
            stats, reads = [], []
            for i in range(1, frames + 1):
                stats.append(s.move("bunny", poses[i]))
                t0 = time.perf_counter()
                s.irradiance()
                reads.append(time.perf_counter() - t0)
            stages = {k: float(np.median([st.seconds[k] for st in stats if k in st.seconds]))
                      for k in dict.fromkeys(k for st in stats for k in st.seconds)}
            total = float(np.median([st.seconds["total"] + r for st, r in zip(stats, reads)]))
            rows.append({"gather": n_rays, "points": len(pts), "photons": photons, "setup_s": s.setup_seconds,
                         "stage_median_s": stages, "read_median_s": float(np.median(reads)),
                         "rays_changed_median": float(np.median([st.rays_changed for st in stats])),
                         "updates_per_s": 1 / total})
        print(f"gather {n_rays}: {rows[-1]['updates_per_s']:.1f} updates/s, {stages}", flush=True)
    return rows


def static_constants(quick, rng):
    """The static points' constants: counted work of an update per changed
    segment and per cbrt(n_S), disc indexing vs the sphere cache (model: 2
    vs 8.08 per recomputed segment, i.e. 1 vs 4.04 per segment streamed)."""
    rows, f = [], 0.1
    engine = room_engine(f, 20_000 if quick else 100_000, 16)
    for n_s in (1_000, 8_000) if quick else (1_000, 8_000, 64_000):
        # random points on the room's walls (static), normals inwards
        face = rng.integers(0, 6, n_s)
        p = rng.uniform(-0.999, 0.999, (n_s, 3))
        axis, sign = face // 2, np.where(face % 2 == 0, -1.0, 1.0)
        p[np.arange(n_s), axis] = sign
        walls = np.hstack([p, np.where(np.eye(3)[axis] > 0, -sign[:, None], 0.0)])
        for method in ("detp_disc_index", "detp_sphere_cache"):
            engine.move("ball", np.eye(4))
            session = oclgi.Session(engine, walls, method=method, radius=0.02, count_work=True)
            work, streamed, secs = {"t": 0, "u": 0, "nodes": 0}, 0, []
            for _ in range(3 if quick else 6):
                before = session.work()
                st = session.move("ball", random_pose(rng, f))
                after = session.work()
                work = {k: v + after[k] - before[k] for k, v in work.items()}
                streamed += st.segments_removed + st.segments_added
                secs.append(st.seconds.get("subtract", 0) + st.seconds.get("add", 0))
            c = np.cbrt(n_s)
            rows.append(r := {"n_S": n_s, "method": method, "streamed": streamed, **work,
                              "t_per_seg_cbrt": work["t"] / streamed / c, "u_per_seg_cbrt": work["u"] / streamed / c,
                              "tu_per_seg_cbrt": (work["t"] + work["u"]) / streamed / c,
                              "nodes_per_seg": work["nodes"] / streamed,
                              "estimate_s_per_seg": float(np.sum(secs)) / streamed})
            print(f"n_S={n_s} {method}: (t+u)/(seg cbrt n_S)={r['tu_per_seg_cbrt']:.2f} "
                  f"t={r['t_per_seg_cbrt']:.2f} u={r['u_per_seg_cbrt']:.2f} nodes/seg={r['nodes_per_seg']:.1f} "
                  f"{r['estimate_s_per_seg'] * 1e9:.0f} ns/seg", flush=True)
    return rows


def dynamic_points(quick, frames=8):
    """Dynamic points (pixels on the moving bunny, Cornell box, f = 0.1):
    disc indexing over the paths near the discs after the update (the
    default), in the find pass (fused), in a pass over the whole store, and
    the sphere cache; counted work and time per update."""
    side = 100 if quick else 316
    engine, base, path_r = scene_engine("cornell", side)
    engine.move("bunny", circle(engine.scene, 0.1, base, path_r, frames, 0))
    photons = photons_for(engine, 1e5 if quick else 1e6)
    rows = []
    for label, dynamic, mode in (("disc index, paths near the discs", "detp_disc_index", "listed"),
                                 ("disc index, fused with find", "detp_disc_index", "find"),
                                 ("disc index, own pass", "detp_disc_index", "store"),
                                 ("sphere cache, own pass", "detp_sphere_cache", "store")):
        for count in (True, False):
            engine.move("bunny", circle(engine.scene, 0.1, base, path_r, frames, 0))
            s = oclgi.Session(engine, method="detp_disc_index", photons=photons, radius=0.03, dynamic=dynamic,
                              count_work=count)
            s.dynamic_pass = mode
            n_r = int(s.segments()[1].sum())
            dyn_work, stats = {"t": 0, "u": 0, "nodes": 0}, []
            for i in range(1, frames + 1):
                before = s.dynamic_work or {"t": 0, "u": 0, "nodes": 0}
                stats.append(s.move("bunny", circle(engine.scene, 0.1, base, path_r, frames, i)))
                after = s.dynamic_work or before
                dyn_work = {k: v + after[k] - before[k] for k, v in dyn_work.items()}
            if count:
                work = {k: v / frames for k, v in dyn_work.items()}
                continue
            rows.append(row := {"label": label, "n_R": n_r, "n_D": float(np.median([st.points for st in stats])),
                                "n_Rec": float(np.median([st.segments_removed for st in stats])), "work": work,
                                "points_s": float(np.median([st.seconds.get("points", 0) for st in stats])),
                                "find_s": float(np.median([st.seconds["find"] for st in stats])),
                                "total_s": float(np.median([st.seconds["total"] for st in stats]))})
            print(f"{label}: n_D={row['n_D']:.0f} work={work} points {row['points_s'] * 1e3:.1f} ms "
                  f"find {row['find_s'] * 1e3:.1f} ms total {row['total_s'] * 1e3:.1f} ms", flush=True)
    return rows


def _table(title, header, rows, row):
    """A markdown section: ``header``'s columns (the first left-aligned, the
    others right-aligned) and ``row(r)``'s cells for each of ``rows``."""
    return (["", f"## {title}", "", f"| {header} |", "|---|" + "---:|" * header.count(" | ")]
            + [f"| {row(r)} |" for r in rows])


STAGES = ("points", "find", "subtract", "retrace", "add", "total")


def markdown(res):
    md = [f"# Incremental update study ({res.get('method', '')})"]
    if res.get("speedup"):
        md += _table("Speedup vs f (room with a ball)", "f | n_Rec/n_R | f^2 | dynamic points | full s | update s | "
                     "S (time) | S (work) | model S(f)", res["speedup"], lambda r: (
                         f"{r['f']:.2f} | {r['n_Rec_over_n_R']:.4f} | {r['f'] ** 2:.4f} | {r['dynamic_points']:.0f} | "
                         f"{r['full_seconds']:.3f} | {r['update_seconds']:.4f} | {r['speedup_time']:.1f} | "
                         f"{r['speedup_work']:.1f} | {r['model']:.1f}"))
    if res.get("constants"):
        md += _table("Static points: counted work per streamed segment and cbrt(n_S)", "n_S | method | segments "
                     "streamed | t | u | (t+u) | nodes / segment | ns / segment", res["constants"], lambda r: (
                         f"{r['n_S']:,} | {r['method']} | {r['streamed']:,} | {r['t_per_seg_cbrt']:.2f} | "
                         f"{r['u_per_seg_cbrt']:.2f} | {r['tu_per_seg_cbrt']:.2f} | {r['nodes_per_seg']:.1f} | "
                         f"{r['estimate_s_per_seg'] * 1e9:.0f}"))
    if res.get("dynamic"):
        md += _table("Dynamic points (Cornell box + bunny, f = 0.1)", "dynamic points by | n_R | n_D | n_Rec | t | u "
                     "| nodes | points ms | find ms | update ms", res["dynamic"], lambda r: (
                         f"{r['label']} | {r['n_R']:,} | {r['n_D']:.0f} | {r['n_Rec']:.0f} | {r['work']['t']:,.0f} | "
                         f"{r['work']['u']:,.0f} | {r['work']['nodes']:,.0f} | {r['points_s'] * 1e3:.1f} | "
                         f"{r['find_s'] * 1e3:.1f} | {r['total_s'] * 1e3:.1f}"))
    if res.get("rate_vs_segments"):
        md += _table("Update rate against the number of stored segments (Cornell box + bunny, f = 0.1, 316 x 316 "
                     "pixels, 30 frames)", "stored segments | updates/s | " + " | ".join(f"{k} ms" for k in STAGES),
                     res["rate_vs_segments"], lambda r: f"{r['n_R']:,} | {r['updates_per_s']:.1f} | " + " | ".join(
                         f"{r['stage_median_s'].get(k, 0) * 1e3:.1f}" for k in STAGES))
    if res.get("gather"):
        keys = ("find", "subtract", "retrace", "add", "gather", "total")
        md += _table("Final gathering in a session (Cornell box + bunny, f = 0.1; sensor points on the floor and "
                     "walls, exact direct light)", "gather rays | points | photons | rays changed per move | "
                     + " | ".join(f"{k} ms" for k in keys) + " | read ms | updates/s (move + read)", res["gather"],
                     lambda r: f"{r['gather']} | {r['points']:,} | {r['photons']:,} | {r['rays_changed_median']:,.0f} | "
                     + " | ".join(f"{r['stage_median_s'].get(k, 0) * 1e3:.1f}" for k in keys)
                     + f" | {r['read_median_s'] * 1e3:.1f} | {r['updates_per_s']:.1f}")
    for inter in res.get("interactive", []):
        md += ["", f"## Interactive rate ({inter['scene']} + bunny, f = {inter['f']})", "",
               f"{inter['n_R']:,} stored segments, {inter['points']:,} query points, {inter['frames']} frames, "
               f"{inter['dynamic_points_median']:.0f} dynamic points and {inter['paths_median']:.0f} re-traced paths "
               f"per frame (median): median update {inter['median_update_s'] * 1e3:.1f} ms = "
               f"**{inter['updates_per_s']:.1f} updates/s** (session set-up {inter['setup_s']:.2f} s).",
               "", "| stage | median ms |", "|---|---:|"]
        md += [f"| {k} | {v * 1e3:.2f} |" for k, v in inter["stage_median_s"].items()]
        md.append(f"\nPeak RSS over the run (MiB, sampled): "
                  f"{', '.join(f'{x:.0f}' for x in inter['max_rss_mib_samples'])}")
    return "\n".join(md) + "\n"


def plot(rows, method):
    fig, ax = figure(figsize=(6, 4.2))
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


def main():
    args = arguments(__doc__, method="detp_disc_index", quick=False,
                     parts=("speedup,constants,dynamic,interactive,segments", "comma-separated: speedup, constants, "
                            "dynamic, interactive, segments (the others keep their last results)"),
                     frames=(100, "frames of the interactive benchmark"),
                     scenes=("cornell,sponza", "scenes of the interactive benchmark"))
    parts = set(args.parts.split(","))
    rng = np.random.default_rng(7)
    path = RESULTS / "update_study.json"
    res = json.loads(path.read_text()) if path.exists() else {}
    if isinstance(res.get("interactive"), dict):  # as earlier versions wrote it
        res["interactive"] = [res["interactive"]]
    res.update(method=args.method, quick=args.quick)
    if "speedup" in parts:
        res["speedup"] = speedup_vs_f(args.method, args.quick, rng)
        plot(res["speedup"], args.method)
    if "constants" in parts:
        res["constants"] = static_constants(args.quick, rng)
    if "dynamic" in parts:
        res["dynamic"] = dynamic_points(args.quick)
    if "segments" in parts:  # the rate against the store's size, Cornell box
        res["rate_vs_segments"] = [interactive("cornell", args.method, args.quick, 30, segments=n)
                                   for n in (1.25e5, 2.5e5, 5e5, 1e6, 2e6)]
    if "gather" in parts:
        res["gather"] = gather_session(args.quick, min(args.frames, 30))
    if "interactive" in parts:
        res["interactive"] = [interactive(name, args.method, args.quick, args.frames)
                              for name in args.scenes.split(",")]
    write("update_study.json", json.dumps(res, indent=1))
    write("update_study.md", md := markdown(res))
    print(md)


if __name__ == "__main__":
    main()
