"""The viewer's update rate as a user sees it: a scripted drag through the browser.

``oclgi view``'s server (in this process) and its page in headless
Chromium (tests/browser.py); the page itself moves the bunny (f = 0.1, as
bench/update_study.py's interactive benchmark) round a circle on the floor,
through the same path a mouse drag takes (``oclgiState.api.move``: the pose
queued, sent at the next display frame, coalesced by the server), and
records per update:

- **sequential**: move (at a display frame), then wait until the frame of
  that move is drawn; as seen, the display frames from the move's to the
  one that draws its colours; the time from the move to its draw finished (the page reads a pixel back
  after drawing a new update's colours) is what the user waits (server
  update + read-back + transfer + decode + the wait for the display frame
  + upload + draw), its inverse the updates per second; the mesh drawn is
  the page's own choice (a level of detail in motion when its exact frame
  misses the budget, oclgi/viewer/static/viewer.js);
- **continuous**: a new pose every display frame for some seconds, as a
  drag does; the frames drawn per second (the server coalesces the poses
  that arrive while it computes).

With the server's per-stage split (``UpdateStats.seconds``: points, find,
subtract, re-trace, add; read: irradiance read back and radiance) and the
dynamic points (the bunny's vertices, recomputed each move from the whole
store). Each scene in two browsers (tests/browser.py): ``software``, what
Chromium chooses by itself without a GPU (WebGL2 on SwiftShader, the page
composited in software), and ``swiftshader``, the compositor on SwiftShader
too. ``python bench/viewer_drag.py [--scenes cornell,sponza] [--browsers
software,swiftshader] [--moves N] [--segments 1e6] [--quick]``; writes
bench/results/viewer_drag.md and .json.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import sys
import threading

import numpy as np

import oclgi
from common import ROOT, arguments, load, timed, write
from oclgi.scene.tessellate import tessellate
from oclgi.viewer.server import Viewer
from update_study import SCENES, photons_for, scaled_pose

sys.path.insert(0, str(ROOT / "tests"))
from browser import CONFIGURATIONS, Browser  # noqa: E402

RADIUS = {"cornell": 0.03, "sponza": 0.3}  # the disc radius of bench/update_study.py's interactive rate
EDGE = {"cornell": 0.06, "sponza": 0.6}  # two disc radii between vertices

SEQUENTIAL = """(async () => {
  const S = oclgiState, out = [], intervals = [], R = %(r)r, N = %(n)d;
  const next = () => new Promise(r => requestAnimationFrame(r));
  S.timeDraws = true;
  // each move is made at a display frame, as Chromium hands a page mouse moves (aligned to its frames)
  let frameAt = await next();
  for (let i = 1; i <= N; i++) {
    const a = 2 * Math.PI * i / N;
    const m = [1, 0, 0, R * (Math.cos(a) - 1), 0, 1, 0, 0, 0, 0, 1, R * Math.sin(a), 0, 0, 0, 1];
    const seq = S.seq, t0 = performance.now(), f0 = frameAt;
    S.api.move("bunny", m);
    while (!(S.seq > seq && S.drawnSeq === S.seq)) {
      const f = await next();
      intervals.push(f - frameAt);
      frameAt = f;
    }
    const u = S.lastUpdate;
    out.push({ms: S.drawnDoneAt - t0, frame_ms: S.frameAt - t0, seen_ms: S.drawnFrameAt - f0, s: u.seconds,
              paths: u.paths, points: u.points, n_rec: u.segments_removed, n_r: u.segments, frame: S.frameStats,
              level: S.drawnLevel, motion: S.drawnMotion, draws: S.draws});
  }
  return {moves: out, intervals};
})()"""

CONTINUOUS = """(async () => {
  const S = oclgiState, R = %(r)r, T = %(t)r * 1000;
  const next = () => new Promise(r => requestAnimationFrame(r));
  const t0 = performance.now();
  let drawn = 0, last = S.drawnSeq, displayFrames = 0;
  while (performance.now() - t0 < T) {
    const a = 2 * Math.PI * (performance.now() - t0) / T;
    S.api.move("bunny", [1, 0, 0, R * (Math.cos(a) - 1), 0, 1, 0, 0, 0, 0, 1, R * Math.sin(a), 0, 0, 0, 1]);
    await next();
    displayFrames++;
    if (S.drawnSeq !== last) { drawn++; last = S.drawnSeq; }
  }
  const synced = await S.api.sync();
  return {seconds: (performance.now() - t0) / 1000, drawn, displayFrames, updates: synced.updates,
          coalesced: synced.coalesced};
})()"""


ORBIT = """(async () => {
  const S = oclgiState, next = () => new Promise(r => requestAnimationFrame(r));
  const t0 = performance.now(), d0 = S.draws;
  while (performance.now() - t0 < 3000) { S.api.orbit(0.002, 0); await next(); }
  return {per_s: (S.draws - d0) / ((performance.now() - t0) / 1000), level: S.drawnLevel, motion: S.drawnMotion};
})()"""


def scene_with_bunny(name: str, f: float = 0.1):
    """The benchmark scene with the bunny scaled to f and standing on the floor (baked into the scene, so
    that the tessellation has it there)."""
    data, base, path_r = SCENES[name]
    data = json.loads(json.dumps(data))
    m = scaled_pose(load(data), "bunny", f, base)
    bunny = next(mesh for mesh in data["mesh"] if mesh.get("name") == "bunny")
    bunny["transform"] = {"scale": float(m[0, 0]), "translate": m[:3, 3].tolist()}
    return load(data), path_r


def serve_in_thread(viewer):
    box, ready = {}, threading.Event()

    def run():
        loop = box["loop"] = asyncio.new_event_loop()
        box["task"] = loop.create_task(viewer.serve("127.0.0.1", 0, lambda url: (box.update(url=url), ready.set())))
        with contextlib.suppress(asyncio.CancelledError):
            loop.run_until_complete(box["task"])

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    if not ready.wait(120):
        raise RuntimeError("the server did not start")
    return box, thread


def bench_scene(name: str, moves: int, segments: float, drag_seconds: float, browser_kind: str) -> dict:
    scene, path_r = scene_with_bunny(name)
    engine = oclgi.Engine(scene, progress=False)
    photons = photons_for(engine, segments)
    tess_s, tess = timed(tessellate, scene, EDGE[name])
    viewer = Viewer(engine, tess, "detp_disc_index", photons, RADIUS[name])
    box, thread = serve_in_thread(viewer)
    try:
        async def drive():
            async with Browser(flags=CONFIGURATIONS[browser_kind]) as browser:
                tab = await browser.open(box["url"])
                await tab.wait("window.oclgiState && oclgiState.ready && oclgiState.frames > 0", timeout=600)
                hello = await tab.eval("oclgiState.hello")
                frame_ms = await tab.eval("oclgiState.frameMs")
                # the exact frame, then the motion frame of each mesh (the tessellation and its levels)
                draw_ms = [await tab.eval("oclgiState.api.drawMs(5, 0, false)")] + [
                    await tab.eval(f"oclgiState.api.drawMs(5, {k}, true)") for k in range(len(viewer.levels) + 1)]
                await tab.eval(SEQUENTIAL % {"r": path_r, "n": 4})  # warm: kernels of the first moves
                seq = await tab.eval(SEQUENTIAL % {"r": path_r, "n": moves})
                seq["features"] = (await browser.call("SystemInfo.getInfo"))["gpu"]["featureStatus"]
                cont = await tab.eval(CONTINUOUS % {"r": path_r, "t": drag_seconds})
                cont["orbit"] = await tab.eval(ORBIT)  # the display alone: frames drawn a second, no server work
                return hello, seq, cont, frame_ms, draw_ms
        hello, seq, cont, frame_ms, draw_ms = asyncio.run(drive())
    finally:
        box["loop"].call_soon_threadsafe(box["task"].cancel)
        thread.join(30)
    interval = float(np.mean(seq["intervals"]))  # the display frame (ms; each time is rounded to 0.1 ms)
    features, seq = seq["features"], seq["moves"]
    ms = np.array([r["ms"] for r in seq])
    frames = np.rint(np.array([r["seen_ms"] for r in seq]) / interval)
    server = np.array([1e3 * r["s"]["server"] for r in seq])

    def med(value):
        return float(np.median([value(r) for r in seq]))

    return {
        "scene": name, "browser": browser_kind, "gpu_compositing": features.get("gpu_compositing"),
        "photons": photons, "segments": hello["segments"], "vertices": len(tess.vertices),
        "dynamic_points": int(np.median([r["points"] for r in seq])), "edge": EDGE[name], "radius": RADIUS[name],
        "tessellate_s": tess_s, "setup_s": hello["setup_seconds"], "moves": moves,
        "faces": len(tess.faces), "levels": [len(lv.faces) for lv in viewer.levels],
        "levels_s": viewer.levels_seconds, "frame_ms_measured": frame_ms, "draw_ms": draw_ms,
        "level_drawn": int(np.median([r["level"] for r in seq])),
        "paths_median": med(lambda r: r["paths"]), "n_rec_median": med(lambda r: r["n_rec"]),
        "user_ms_median": float(np.median(ms)), "user_ms_p90": float(np.percentile(ms, 90)),
        "draw_done_per_s": 1e3 / float(np.median(ms)),
        # as seen: the display frames from the move's to the one that shows its colours
        "display_frame_ms": interval, "frames_seen_median": float(np.median(frames)),
        "within_2_frames": float(np.mean(frames <= 2)), "within_3_frames": float(np.mean(frames <= 3)),
        "updates_per_s": 1e3 / (float(np.median(frames)) * interval),
        "draws_per_update": (seq[-1]["draws"] - seq[0]["draws"]) / max(len(seq) - 1, 1),
        "stage_ms_median": {k: float(np.median([1e3 * r["s"][k] for r in seq if k in r["s"]]))
                            for k in dict.fromkeys(k for r in seq for k in r["s"])},
        "client_ms_median": float(np.median(ms - server)),
        # move queued -> its frame applied, less the server's time: sending, the socket both ways, decoding
        "transfer_ms_median": float(np.median(np.array([r["frame_ms"] for r in seq]) - server)),
        # frame applied -> drawn: waiting for the display frame, upload and draw
        "draw_ms_median": med(lambda r: r["ms"] - r["frame_ms"]),
        "continuous": cont, "continuous_per_s": cont["drawn"] / cont["seconds"],
        # the colour frames: bytes sent, vertices in them, and the bytes the float32 per-index format took
        # (16 + 16 per changed vertex, or 12 per vertex whole); the page's time to apply one
        "frame_kb_median": med(lambda r: r["frame"]["bytes"]) / 1024,
        "frame_vertices_median": med(lambda r: r["frame"]["vertices"]),
        "float32_frame_kb_median":
            med(lambda r: 16 + min(16 * r["frame"]["vertices"], 12 * len(tess.vertices))) / 1024,
        "apply_ms_median": med(lambda r: r["frame"]["applyMs"]),
        "without_dynamic_ms": static_points_cost(viewer, path_r, moves),
    }


def static_points_cost(viewer, path_r: float, moves: int) -> dict:
    """The same moves in the API, with and without the bunny's vertices (the
    dynamic points): median ms of session.move, the points' share."""
    from oclgi.incremental.open_session import open_session

    points = viewer.points
    on_bunny = np.zeros(len(points), bool)
    for name in viewer.movable:
        a, b = viewer.engine.scene.object_ranges()[viewer.engine.scene.object_id(name)]
        on_bunny |= (points.tri >= a) & (points.tri < b)
    out = {}
    for label, pts in (("all", points), ("static only", points.subset(np.nonzero(~on_bunny)[0]))):
        r = viewer.run
        with open_session(viewer.engine, pts, method=r.method, photons=r.photons, radius=r.radius) as s:
            t = []
            for a in 2 * np.pi * np.arange(1, moves + 1) / moves:
                m = np.eye(4)
                m[0, 3], m[2, 3] = path_r * (np.cos(a) - 1), path_r * np.sin(a)
                t.append(s.move("bunny", m).seconds["total"])
        out[label] = 1e3 * float(np.median(t[2:]))
    return out


def markdown(rows: list[dict], machine: str) -> str:
    stages = ["points", "find", "subtract", "retrace", "add", "total", "read", "server"]
    out = ["# Viewer: a scripted drag through the browser", "", machine, "",
           "Browsers: `software`, Chromium's own choice without a GPU (WebGL2 on SwiftShader, the page "
           "composited in software); `swiftshader`, the compositor through SwiftShader too (the tests' browser).", "",
           "Per update, median ms: the server's stages (`UpdateStats.seconds`; read: irradiance read back "
           "and radiance), its whole time (server), and what the user waits from the move to its frame drawn "
           "(user: + transfer: the move sent, the frame back and decoded; + draw: the wait for the display frame, "
           "upload and draw, a pixel read back). Seen: the display frames from the move's (made at a frame, as "
           "Chromium hands a page its mouse moves) to the one that shows its colours, median and the share within "
           "two and three; updates/s as seen = 1 / (median frames x the frame's time); draws: frames drawn per "
           "update. Drag frames/s: frames with new colours drawn per second during a continuous drag (a pose "
           "every display frame, coalesced).", "",
           "| scene | browser | vertices / dynamic | photons / segments | paths re-traced | "
           + " | ".join(stages) + " | transfer | draw | user | seen (frames) | <= 2 / <= 3 | updates/s as seen "
           "| draws | drag frames/s |",
           "|---|---|---:|---:|---:|" + "---:|" * len(stages) + "---:|---:|---:|---:|---:|---:|---:|---:|"]
    out += [f"| {r['scene']} + bunny | {r['browser']} | {r['vertices']:,} / {r['dynamic_points']:,} | "
            f"{r['photons']:,} / {r['segments']:,} | {r['paths_median']:,.0f} | "
            + " | ".join(f"{r['stage_ms_median'].get(k, float('nan')):.1f}" for k in stages)
            + f" | {r['transfer_ms_median']:.1f} | {r['draw_ms_median']:.1f} | {r['user_ms_median']:.1f} | "
            f"{r['frames_seen_median']:g} | {100 * r['within_2_frames']:.0f}% / {100 * r['within_3_frames']:.0f}% | "
            f"**{r['updates_per_s']:.1f}** | {r['draws_per_update']:.2f} | {r['continuous_per_s']:.1f} |"
            for r in rows]
    out += ["", "The meshes the page draws: the tessellation and its levels of detail (faces); the draw times "
            "(`oclgiState.api.drawMs`: colours uploaded, drawn, a pixel read back) of the exact frame and of "
            "each mesh's motion frame (half the resolution each way, sRGB per vertex); the mesh a drag draws "
            "(0: the tessellation; the finest whose motion frame fits the page's budget) and the levels' "
            "build time on the server:", "",
            "| scene | faces: full / levels | draw ms: exact / motion full / levels | mesh drawn in a drag | "
            "orbit frames/s | levels built (s) |",
            "|---|---:|---:|---:|---:|---:|"]
    out += [f"| {r['scene']} + bunny ({r['browser']}) | {r['faces']:,} / {' / '.join(f'{g:,}' for g in r['levels'])} | "
            f"{' / '.join(f'{t:.1f}' for t in r['draw_ms'])} | {r['level_drawn']} | "
            f"{r['continuous']['orbit']['per_s']:.0f} | {r['levels_s']:.2f} |"
            for r in rows]
    out += ["", "The colour frames (median per update): float16 runs and single indices against the float32 "
            "per-index format, the vertices they carry, the page's time to apply one:", "",
            "| scene | vertices in a frame | frame KB | float32 format KB | apply ms |", "|---|---:|---:|---:|---:|"]
    out += [f"| {r['scene']} + bunny ({r['browser']}) | {r['frame_vertices_median']:,.0f} | {r['frame_kb_median']:.0f} | "
            f"{r['float32_frame_kb_median']:.0f} | {r['apply_ms_median']:.2f} |" for r in rows]
    out += ["", "The dynamic points' cost: the same moves through the API (session.move, median ms), over the "
            "viewer's query points and over the static vertices only:", "", "| scene | query points | static only |", "|---|---:|---:|"]
    out += [f"| {r['scene']} + bunny ({r['browser']}) | {w['all']:.1f} | {w['static only']:.1f} |"
            for r in rows for w in [r["without_dynamic_ms"]]]
    return "\n".join(out) + "\n"


def main():
    args = arguments(__doc__, scenes="cornell,sponza", moves=60, segments=1e6, drag_seconds=5.0,
                     browsers="software,swiftshader", quick=dict(segments=1e5, moves=10, drag_seconds=2.0))
    rows = [bench_scene(name, args.moves, args.segments, args.drag_seconds, kind)
            for name in args.scenes.split(",") for kind in args.browsers.split(",")]
    from oclgi.cl.device import describe_devices

    machine = f"Device: {describe_devices().splitlines()[0].strip()}; load average {os.getloadavg()[0]:.2f}."
    write("viewer_drag.json", json.dumps({"machine": machine, "rows": rows}, indent=1))
    write("viewer_drag.md", md := markdown(rows, machine))
    print(md)


if __name__ == "__main__":
    main()
