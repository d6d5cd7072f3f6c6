"""What tests/test_distributed.py runs under ``mpiexec -n K``: distributed
runs through oclgi.distributed, rank 0 writing the results as .npy files.

    python mpi_worker.py irradiance OUT      every estimator on the Cornell box's camera points
    python mpi_worker.py session OUT MOVES   every incremental method, the moves of MOVES (.npy)
    python mpi_worker.py fail OUT RANK WHAT  rank RANK alone is given something else (WHAT:
                                             method, photons, device, bug, interrupt,
                                             collective)

Errors end the way the command line ends them: one line from rank 0
(``oclgi: error: ...``), exit status 2 on every rank.
"""

import sys
import tomllib
from pathlib import Path

import numpy as np

import oclgi
from oclgi import distributed
from oclgi.errors import OclgiError

HERE = Path(__file__).resolve().parent
SCENES = HERE.parent / "scenes"

# shared with the test, which computes the same in one process
METHODS = ["detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache", "impact", "photon_map", "ray_map_knn"]
INCREMENTAL = ["detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache", "impact"]
PHOTONS = 20_000
RADIUS = 0.1
VIEW = (8, 8)  # camera points of the Cornell box: 64
SESSION_RADIUS = 0.15
SESSION_POINTS = 64
WORK_KEYS = ("t", "u", "nodes")
GATHER = dict(method="detp_disc_index", photons=PHOTONS, radius=RADIUS, direct="exact", gather=8)
# the Cornell box's area light sampled with MIS (the default sample count: the whole request's)
AREA = dict(method="detp_disc_index", photons=PHOTONS, radius=RADIUS, direct="exact")


def cornell_points(engine):
    return engine.camera_points(width=VIEW[0], height=VIEW[1])


def block_scene():
    from small_scene import MOVING_BLOCK

    return oclgi.load_dict(tomllib.loads(MOVING_BLOCK))


def floor_points(n=SESSION_POINTS):
    """Points on the moving-block scene's floor, facing up."""
    rng = np.random.default_rng(7)
    p = np.column_stack([rng.uniform(-0.9, 0.9, n), np.zeros(n), rng.uniform(-0.9, 0.9, n)])
    return np.column_stack([p, np.tile([0.0, 1.0, 0.0], (n, 1))])


def _save(out, name, a):
    np.save(out / f"{name}.npy", np.asarray(a))


def irradiance(comm, out):
    scene = distributed.load_scene(comm, SCENES / "cornell_box.toml")
    engine = oclgi.Engine(scene)
    root = distributed.is_root(comm)
    pts = cornell_points(engine) if root else None
    for m in METHODS:
        est = distributed.irradiance(engine, pts, comm, method=m, photons=PHOTONS, radius=RADIUS)
        if root:
            _save(out, f"{m}_acc", est.accumulators)
            _save(out, f"{m}_irr", est.irradiance)
            _save(out, f"{m}_segments", est.stats.segments)
    # the exact work counters are summed too (uint64)
    est = distributed.irradiance(engine, pts, comm, method="detp_disc_index", photons=PHOTONS, radius=RADIUS,
                                 count_work=True)
    if root:
        _save(out, "work", [est.work[k] for k in WORK_KEYS])
    result = distributed.render(engine, comm, width=VIEW[0], height=VIEW[1], method="detp_disc_index",
                                photons=PHOTONS, radius=RADIUS)
    if root:
        _save(out, "render_radiance", result.radiance)
        _save(out, "render_pixels", result.pixels)
    est = distributed.irradiance(engine, pts, comm, **AREA)
    if root:
        _save(out, "area_irr", est.irradiance)
    # final gathering (a delta light: the IES downlight): its sums are the hits'
    ies = oclgi.Engine(distributed.load_scene(comm, SCENES / "cornell_ies.toml"))
    est = distributed.irradiance(ies, cornell_points(ies) if root else None, comm, **GATHER)
    if root:
        _save(out, "gather_acc", est.accumulators)
        _save(out, "gather_irr", est.irradiance)


def session(comm, out, moves_file):
    engine = oclgi.Engine(block_scene())
    root = distributed.is_root(comm)
    moves = np.load(moves_file) if root else None
    n_moves = distributed.share(comm, None if moves is None else len(moves))
    for m in INCREMENTAL:
        engine.move("block", np.eye(4))
        s = distributed.Session(engine, floor_points() if root else None, comm, method=m, photons=PHOTONS,
                                radius=SESSION_RADIUS)
        frame_bytes = []
        for i in range(n_moves):
            s.move("block", moves[i] if root else None)
            frame_bytes.append(s.frame_bytes)
        irr = s.irradiance()
        if root:
            _save(out, f"{m}_acc", s.accumulators())
            _save(out, f"{m}_irr", irr)
            _save(out, f"{m}_bytes", [frame_bytes, [s.full_bytes] * len(frame_bytes)])


def fail(comm, out, rank, what):
    """Every rank runs the same except rank ``rank``: another parameter, or an exception of its own."""
    mine = comm.rank == rank
    device = "no such device" if mine and what == "device" else None
    engine = distributed.engine(comm, SCENES / "cornell_box.toml", device=device)
    args = dict(method="detp", photons=PHOTONS, radius=RADIUS)
    if mine and what == "method":
        args["method"] = "no_such_method"
    elif mine and what == "photons":
        args["photons"] = PHOTONS + 1  # valid, but not the other ranks' run
    elif mine and what == "bug":
        def broken(*a, **k):
            raise RuntimeError("a bug in the run")
        engine.run = broken
    elif mine and what == "interrupt":  # Ctrl-C reaching one rank
        def interrupted(*a, **k):
            raise KeyboardInterrupt
        engine.run = interrupted
    elif mine and what == "collective":  # a failure inside an MPI exchange: the job is aborted
        def broken(*a, **k):
            raise RuntimeError("an exchange broke")
        distributed._reduce_state = broken
    pts = cornell_points(engine) if comm.rank == 0 else None
    distributed.irradiance(engine, pts, comm, **args)
    if comm.rank == 0:
        _save(out, "finished", 1)


def main(argv):
    mode, out = argv[0], Path(argv[1])
    comm = distributed.world()
    try:
        if mode == "irradiance":
            irradiance(comm, out)
        elif mode == "session":
            session(comm, out, argv[2])
        elif mode == "fail":
            fail(comm, out, int(argv[2]), argv[3])
        else:
            raise SystemExit(f"unknown mode {mode!r}")
    except distributed.PeerError:
        return 2  # rank 0 prints it
    except OclgiError as exc:
        print(f"oclgi: error: {exc}", file=sys.stderr, flush=True)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
