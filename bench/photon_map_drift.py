"""Photon Maps under moves: how far the practical update drifts from recomputation.

The Cornell box with the bunny (``scenes/cornell_bunny.toml``, its 10^5
photon paths, k = 50, the k-1 estimator). Query points: random points on
the room's surfaces (normals into the room) and on the bunny (attached to
it). The bunny goes once round a circle on the floor, turning as it goes,
in small steps; the last frame is the first pose again.

Per frame, at the same pose:

- the practical session's irradiance (oclgi.PhotonMapSession, mode
  "practical") against a Photon Map estimate from scratch with the same
  seed: relative RMS and largest error over the room's points (the
  bunny's points are searched again, so they match: checked);
- an exact-mode session, checked equal to the recomputation bit for bit;
- the estimator's own noise, every few frames: two recomputations with
  different seeds (the RMS of their difference over sqrt 2 is one
  estimate's noise);
- "frozen": the error if the room's points kept their first-frame
  estimates (the map updated, nothing re-estimated), for comparison;
- times: a practical update, an exact update, a practical update when no
  point lies on the bunny, and a full recomputation (trace, gather, index,
  search), in the same run.

Writes ``bench/results/photon_map_drift.{json,md,png}``.
Usage: ``.venv/bin/python bench/photon_map_drift.py [--frames N] [--quick]``.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

import oclgi
from common import RESULTS, arguments, concat, engine as make_engine, figure, timed, write


def surface_points(scene, obj, n, rng, towards=None):
    """n area-weighted random points on object ``obj``'s triangles, attached to
    their triangle (``tri``); normals turned towards ``towards`` when given."""
    a, b = scene.object_ranges()[obj]
    areas = scene.triangle_areas()[a:b]
    tri = a + rng.choice(b - a, n, p=areas / areas.sum())
    p = np.einsum("rk,rkc->rc", rng.dirichlet([1, 1, 1], n), scene.vertices[scene.faces[tri]])
    nrm = scene.triangle_normals()[tri]
    if towards is not None:
        nrm *= np.where(np.einsum("ij,ij->i", nrm, np.asarray(towards) - p) < 0, -1, 1)[:, None]
    q = oclgi.query_points(p, nrm)
    q.positions[:, 3] = tri.astype(np.int32).view(np.float32)
    return q


def pose(i, frames, radius=0.3):
    """Frame i of a circle of ``radius`` on the floor, a quarter turn of yaw
    at most; frame 0 and frame ``frames`` are the identity."""
    m = np.eye(4)
    if i % frames == 0:
        return m  # exactly (cos 2 pi is 1, but sin 2 pi is not 0)
    a = 2 * math.pi * i / frames
    yaw = 0.5 * math.sin(a)
    m[:3, :3] = [[math.cos(yaw), 0, math.sin(yaw)], [0, 1, 0], [-math.sin(yaw), 0, math.cos(yaw)]]
    # rotate about the bunny's own spot (its file position), then carry it round the circle
    c = np.array([-0.5, 0.0, 0.55])
    m[:3, 3] = c - m[:3, :3] @ c + [radius * (1 - math.cos(a)), 0, -radius * math.sin(a)]
    return m


def errors(got, ref):
    """Relative RMS and largest error (over the mean), all channels of all points."""
    d = got.astype(np.float64) - ref
    scale = float(np.sqrt(np.mean(np.square(ref))))
    return float(np.sqrt(np.mean(np.square(d))) / scale), float(np.abs(d).max() / np.mean(ref))


def run(frames, photons, n_room, n_bunny, noise_every, seed2=2):
    engine = make_engine("cornell_bunny.toml")
    scene = engine.scene
    # Placed once by a move, so that the last frame (the identity again) is the
    # first frame's scene bit for bit: a move computes the object's world normals
    # on the device, loading computed them on the host, and they differ in the
    # last bits.
    engine.move("bunny", np.eye(4))
    rng = np.random.default_rng(11)
    room = surface_points(scene, 0, n_room, rng, towards=[0, 1, 0])
    pts = concat([room, surface_points(scene, scene.object_id("bunny"), n_bunny, rng)])
    kw = dict(photons=photons, k=50, estimator="k-1")
    practical = oclgi.PhotonMapSession(engine, pts, **kw)
    exact = oclgi.PhotonMapSession(engine, pts, mode="exact", **kw)
    static_only = oclgi.PhotonMapSession(engine, room, **kw)
    frozen = practical.irradiance()[:n_room].copy()
    n_impacts = len(practical.impacts()[0])
    rows = []
    for i in range(1, frames + 1):
        m = pose(i, frames)
        st_p = practical.move("bunny", m)
        st_e = exact.move("bunny", m)
        st_s = static_only.move("bunny", m)
        t_full, ref = timed(practical.recompute)
        e_p = practical.irradiance()
        assert np.array_equal(exact.accumulators(), ref.accumulators), f"frame {i}: exact mode differs"
        assert np.array_equal(e_p[n_room:], ref.irradiance[n_room:]), f"frame {i}: bunny points differ"
        rms, mx = errors(e_p[:n_room], ref.irradiance[:n_room])
        f_rms, f_max = errors(frozen, ref.irradiance[:n_room])
        row = {"frame": i, "drift_rms": rms, "drift_max": mx, "frozen_rms": f_rms, "frozen_max": f_max,
               "points_differing": int((practical.accumulators()[:n_room] != ref.accumulators[:n_room])
                                       .any(axis=1).sum()),
               "paths": st_p.paths, "segments_changed": st_p.segments_removed + st_p.segments_added,
               "exact_points_searched": st_e.points,
               "seconds": {"practical": st_p.seconds["total"], "exact": st_e.seconds["total"],
                           "practical_no_attached": st_s.seconds["total"], "recompute": t_full,
                           "practical_stages": st_p.seconds}}
        if i % noise_every == 0 or i == frames:
            other = practical.recompute(seed=seed2).irradiance
            n_rms, n_max = errors(other[:n_room], ref.irradiance[:n_room])
            row.update(noise_rms=n_rms / math.sqrt(2), noise_max=n_max)
        rows.append(row)
        print(f"frame {i:3d}: drift rms {rms:.4f} max {mx:.3f} | frozen rms {f_rms:.4f}"
              + (f" | noise rms {row['noise_rms']:.4f} max {row['noise_max']:.3f}" if "noise_rms" in row else "")
              + f" | practical {st_p.seconds['total'] * 1e3:.0f} ms, exact {st_e.seconds['total'] * 1e3:.0f} ms"
              f" ({st_e.points} searched), recompute {t_full * 1e3:.0f} ms", flush=True)
    dev = engine.queue.device
    return {"scene": "cornell_bunny.toml", "photons": photons, "k": 50, "estimator": "k-1",
            "impacts": n_impacts, "room_points": n_room, "bunny_points": n_bunny, "frames": frames,
            "machine": {"device": dev.name.strip(), "platform": dev.platform.version.split(",")[0].strip(),
                        "cores": os.cpu_count(), "load_average": os.getloadavg()}, "rows": rows}


def summary(res):
    rows = res["rows"]
    med = lambda key: float(np.median([r["seconds"][key] for r in rows]))  # noqa: E731
    noise = [r for r in rows if "noise_rms" in r]
    return {
        "drift_rms_max": max(r["drift_rms"] for r in rows),
        "drift_rms_median": float(np.median([r["drift_rms"] for r in rows])),
        "drift_max_max": max(r["drift_max"] for r in rows), "drift_rms_last": rows[-1]["drift_rms"],
        "noise_rms_mean": float(np.mean([r["noise_rms"] for r in noise])),
        "noise_max_mean": float(np.mean([r["noise_max"] for r in noise])),
        "frozen_rms_max": max(r["frozen_rms"] for r in rows),
        "median_seconds": {k: med(k) for k in ("practical", "exact", "practical_no_attached", "recompute")},
        "stage_median_seconds": {k: float(np.median([r["seconds"]["practical_stages"].get(k, 0.0) for r in rows]))
                                 for k in rows[0]["seconds"]["practical_stages"]},
        "exact_points_searched_median": float(np.median([r["exact_points_searched"] for r in rows])),
        "paths_median": float(np.median([r["paths"] for r in rows]))}


def report(res):
    s = res["summary"] = summary(res)
    rows, ms = res["rows"], s["median_seconds"]
    n_pts = res["room_points"] + res["bunny_points"]
    md = ["# Photon Maps: practical update and drift", "",
          f"{res['scene']}, {res['photons']:,} photon paths ({res['impacts']:,} impacts), k = {res['k']}, "
          f"estimator {res['estimator']}; {res['room_points']:,} points on the room, {res['bunny_points']} on the "
          f"bunny; {res['frames']} frames, once round a circle (the last frame is the first pose). "
          f"Machine: {res['machine']['device']}, {res['machine']['platform']}, {res['machine']['cores']} cores, "
          f"load average at the end {', '.join(f'{x:.1f}' for x in res['machine']['load_average'])}.", "",
          "Errors over the room's points, all channels: RMS relative to the RMS irradiance; max = largest "
          "|error| over the mean irradiance. Noise: one estimate's, from two seeds.", "",
          f"- drift (practical vs recomputation): RMS median {s['drift_rms_median']:.4f}, "
          f"largest {s['drift_rms_max']:.4f}; max error up to {s['drift_max_max']:.3f}; "
          f"last frame (first pose) {s['drift_rms_last']:.4f}",
          f"- noise of the estimator: RMS {s['noise_rms_mean']:.4f}, max {s['noise_max_mean']:.3f} (mean over "
          f"{sum('noise_rms' in r for r in rows)} frames)",
          f"- frozen room estimates (not re-estimated): RMS up to {s['frozen_rms_max']:.4f}", "",
          "| update | median ms | recompute / update |", "|---|---:|---:|"]
    for key, label in (("practical", f"practical ({res['bunny_points']} points on the bunny searched)"),
                       ("practical_no_attached", "practical, no point on the bunny"),
                       ("exact", f"exact (median {s['exact_points_searched_median']:.0f} of {n_pts:,} points searched)"),
                       ("recompute", "recomputation from scratch")):
        md.append(f"| {label} | {ms[key] * 1e3:.1f} | {ms['recompute'] / ms[key]:.1f} |")
    md += ["", "Practical update stages (median ms): "
           + ", ".join(f"{k} {v * 1e3:.1f}" for k, v in s["stage_median_seconds"].items()), "",
           "| frame | drift RMS | drift max | noise RMS | noise max | frozen RMS | room points differing | paths |",
           "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    md += [f"| {r['frame']} | {r['drift_rms']:.4f} | {r['drift_max']:.3f} | {r['noise_rms']:.4f} | "
           f"{r['noise_max']:.3f} | {r['frozen_rms']:.4f} | {r['points_differing']} | {r['paths']} |"
           for r in rows if "noise_rms" in r]
    write("photon_map_drift.md", "\n".join(md) + "\n")
    write("photon_map_drift.json", json.dumps(res, indent=1))

    f = [r["frame"] for r in rows]
    nf = [r["frame"] for r in rows if "noise_rms" in r]
    fig, axes = figure(1, 2, figsize=(10, 3.8))
    for ax, key, title in ((axes[0], "rms", "relative RMS error"), (axes[1], "max", "largest error / mean E")):
        ax.plot(f, [r[f"drift_{key}"] for r in rows], "o-", ms=3, label="practical vs recomputation")
        ax.plot(nf, [r[f"noise_{key}"] for r in rows if "noise_rms" in r], "s--", ms=4,
                label="estimator noise (two seeds)" + (", per estimate" if key == "rms" else ""))
        ax.plot(f, [r[f"frozen_{key}"] for r in rows], ":", color="grey", label="room estimates frozen")
        ax.set(xlabel="frame", title=title, ylim=(0, None))
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Photon Maps, practical update: {res['photons']:,} photons, k = {res['k']}, "
                 f"bunny once round a circle", fontsize=10)
    fig.tight_layout()
    fig.savefig(RESULTS / "photon_map_drift.png", dpi=110)
    print("\n".join(md[:12]))


def main():
    args = arguments(__doc__, frames=80, photons=dict(type=int, help="default: the scene's (10^5)"),
                     quick=(False, "20 frames, 2x10^4 photons"))
    frames = 20 if args.quick else args.frames
    photons = args.photons or (20_000 if args.quick else 100_000)
    res = run(frames, photons, n_room=4000, n_bunny=400, noise_every=max(frames // 16, 1))
    report(res)


if __name__ == "__main__":
    main()
