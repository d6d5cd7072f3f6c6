"""Runs over MPI ranks on one machine (oclgi/distributed.py): strong scaling
and what a distributed session sends per frame.

    python bench/distributed_scaling.py [--photons 2000000] [--ranks 1 2] [--json FILE]

Launches itself under the environment's ``mpiexec -n K`` for each K and
prints, from rank 0:

1. strong scaling: one DETP disc-index run on the Cornell box (64 x 64
   camera points), its wall time with K ranks, twice: with PoCL's default
   threads (every rank uses every core, so ranks compete for them) and with
   one PoCL thread per rank (ranks as the only parallelism: the shape of K
   machines);
2. a distributed session (the Cornell box with a movable bunny), for jumps
   (the bunny anywhere in the room) and a drag (1 cm a move): per move, the
   bytes the other ranks send rank 0 (changed rows only, as
   ``distributed.Session`` does, and what a Reduce of every row would send)
   against the move's compute time.

Every run is warmed first (kernels compiled); times are wall clock between
barriers, so they include the reduction.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import oclgi
from common import ROOT, arguments
from oclgi import distributed

sys.path.insert(0, str(ROOT / "tests"))  # the tests' rigid motions
from test_instances import _rigid  # noqa: E402

SCENES = ROOT / "scenes"


# -- run under mpiexec ---------------------------------------------------------------


def _comm():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def worker_scaling(photons: int, side: int) -> dict:
    comm = _comm()
    engine = oclgi.Engine(distributed.load_scene(comm, SCENES / "cornell_box.toml"))
    pts = engine.camera_points(width=side, height=side) if comm.rank == 0 else None
    args = dict(method="detp_disc_index", progress=False)
    distributed.irradiance(engine, pts, comm, photons=max(comm.size, 10_000), **args)  # compiles the kernels
    comm.Barrier()
    t0 = time.perf_counter()
    est = distributed.irradiance(engine, pts, comm, photons=photons, **args)
    comm.Barrier()
    wall = time.perf_counter() - t0
    if comm.rank:
        return {}
    return {"ranks": comm.size, "photons": photons, "points": side * side, "wall_s": wall,
            "reduce_s": est.stats.seconds.get("reduce", 0.0), "trace_s": est.stats.seconds["trace"],
            "estimate_s": est.stats.seconds["estimate"], "reduced_bytes": int(est.accumulators.nbytes)}


def worker_session(photons: int, side: int, moves: int, drag: bool) -> dict:
    comm = _comm()
    engine = oclgi.Engine(oclgi.load_dict({
        "mesh": [
            {"path": str(SCENES / "cornell-box" / "CornellBox-Original.obj")},
            {"path": str(SCENES / "stanford-bunny" / "bun_zipper.ply"), "movable": True, "name": "bunny",
             "transform": {"scale": 4.0, "translate": [0.3, -0.13, 0.3]}, "albedo": [0.8, 0.8, 0.8]},
        ],
        "camera": {"position": [0, 1, 3.94], "look_at": [0, 1, 0], "fov": 39.3},
        "photons": {"seed": 21, "max_depth": 10},
    }, base_dir=SCENES))
    pts = engine.camera_points(width=side, height=side) if comm.rank == 0 else None
    t0 = time.perf_counter()
    session = distributed.Session(engine, pts, comm, method="detp_disc_index", photons=photons, radius=0.05)
    comm.Barrier()
    setup = time.perf_counter() - t0
    rng = np.random.default_rng(5)
    frames = []
    for i in range(moves):
        if drag:  # an interactive drag: 1 cm a frame across the floor
            m = np.eye(4)
            m[0, 3] = -0.01 * (i + 1)
        else:  # jumps: anywhere in the room, any orientation
            m = _rigid(rng, 0.5)  # tests/test_instances.py: a random rigid motion
            m[1, 3] = abs(m[1, 3])
        comm.Barrier()
        t1 = time.perf_counter()
        stats = session.move("bunny", m)
        comm.Barrier()
        frames.append({"wall_s": time.perf_counter() - t1, "reduce_s": stats.seconds["reduce"],
                       "paths": stats.paths, "bytes": session.frame_bytes, "rows": session.frame_rows})
    if comm.rank:
        return {}
    return {"ranks": comm.size, "photons": photons, "points": side * side, "setup_s": setup,
            "full_bytes": session.full_bytes, "frames": frames}


def worker(argv):
    if argv[0] == "scaling":
        out = worker_scaling(int(argv[1]), int(argv[2]))
    else:
        out = worker_session(int(argv[1]), int(argv[2]), int(argv[3]), argv[4] == "drag")
    if out:
        print("RESULT " + json.dumps(out), flush=True)


# -- the driver --------------------------------------------------------------------------


def launch(ranks: int, *args, threads: int | None = None) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    if threads:  # PoCL 3's name and PoCL 4's
        env["POCL_MAX_PTHREAD_COUNT"] = env["POCL_CPU_MAX_CU_COUNT"] = str(threads)
    mpiexec = Path(sys.executable).parent / "mpiexec"
    proc = subprocess.run([str(mpiexec), "-n", str(ranks), sys.executable, __file__, "--worker", *map(str, args)],
                          env=env, capture_output=True, text=True, timeout=3600)
    if proc.returncode:
        sys.exit(f"mpiexec -n {ranks} failed:\n{proc.stdout}\n{proc.stderr}")
    line = next(line for line in proc.stdout.splitlines() if line.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


def main():
    if sys.argv[1:2] == ["--worker"]:
        return worker(sys.argv[2:])
    a = arguments(__doc__, photons=2_000_000, side=(64, "camera points per side"),
                  ranks=dict(type=int, nargs="+", default=[1, 2]), session_photons=200_000, moves=20,
                  only=dict(choices=["scaling", "session"], help="one part only"), json=dict(type=Path))
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at the start\n")

    results = {"scaling": [], "session": []}
    if a.only != "session":
        scaling(a, results)
    if a.only != "scaling":
        session(a, results)
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")
    if a.json:
        a.json.write_text(json.dumps(results, indent=1))


def scaling(a, results):
    print(f"Strong scaling: detp_disc_index, Cornell box, {a.photons:,} photons, {a.side}x{a.side} points")
    print("| PoCL threads per rank | ranks | wall s | speed-up | trace s (rank 0) | reduce s |\n" + "|---" * 6 + "|")
    for threads in (None, 1):
        base = None
        for k in a.ranks:
            r = launch(k, "scaling", a.photons, a.side, threads=threads)
            r["threads"] = threads or "default"
            results["scaling"].append(r)
            base = base or r["wall_s"]  # the first count of ranks' time
            print(f"| {r['threads']} | {k} | {r['wall_s']:.2f} | {base / r['wall_s']:.2f} | "
                  f"{r['trace_s']:.2f} | {r['reduce_s']:.4f} |")


def session(a, results):
    print(f"\nDistributed session: Cornell box and bunny, {a.session_photons:,} photons, "
          f"{a.side}x{a.side} fixed points, {a.moves} moves (changed rows: all ranks')")
    print("| moves | ranks | move wall s (median) | reduce s (median) | bytes sent per move (median, max) | "
          "a full Reduce's bytes | changed rows (median) | paths re-traced by rank 0 (median) |\n"
          "|---|---|---|---|---|---|---|---|")
    for kind in ("jumps", "drag"):
        for k in a.ranks:
            r = launch(k, "session", a.session_photons, a.side, a.moves, kind)
            r["moves"] = kind
            results["session"].append(r)
            f = r["frames"]
            med = lambda key: float(np.median([x[key] for x in f]))  # noqa: E731,B023
            print(f"| {kind} | {k} | {med('wall_s'):.3f} | {med('reduce_s'):.4f} | {med('bytes'):,.0f}, "
                  f"{max(x['bytes'] for x in f):,} | {r['full_bytes']:,} | {med('rows'):,.0f} | "
                  f"{med('paths'):,.0f} |")


if __name__ == "__main__":
    main()
