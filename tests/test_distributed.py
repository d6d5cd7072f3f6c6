"""Runs over MPI ranks (oclgi/distributed.py) equal one process bit for bit.

Each test launches ``mpiexec -n 2`` and, in the full suite, ``-n 3`` (3 ranks
oversubscribe a small machine, which MPICH allows; a range split in three
is the uneven case) on tests/mpi_worker.py, whose rank 0
writes its results as .npy files, and compares them with the same
computation made here in one process: the accumulators and irradiance of
every estimator, the exact direct light of an area light (light samples
and MIS), a final gathering, a render, and the sums of every incremental method after
20 moves. An error on one rank must end every rank, with one message.
"""

import csv
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mpi_worker as worker
import oclgi
from oclgi import distributed
from oclgi.tracing.run import PathRange
from test_session import _moves

HERE = Path(__file__).resolve().parent
WORKER = HERE / "mpi_worker.py"
MPIEXEC = Path(sys.executable).parent / "mpiexec"
TIMEOUT = 120  # seconds: a hung rank fails the test instead of the suite
N_MOVES = 20


def _env():
    """This tree's package and kernels, and the suite's private kernel cache
    (conftest.py set POCL_CACHE_DIR), for every rank; no launcher variables
    of an MPI job this test itself might run in."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PMI_", "OMPI_", "PMIX_"))}
    env["PYTHONPATH"] = os.pathsep.join([str(HERE.parent), str(HERE), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env.setdefault("OCLGI_KERNEL_DIR", str(HERE.parent / "kernels"))
    return env


# 2 ranks in `make test`, 3 as well in the full suite (README.md, Tests)
RANKS = [2, pytest.param(3, marks=pytest.mark.full)]


def mpiexec(ranks, *args, timeout=TIMEOUT):
    return subprocess.run([str(MPIEXEC), "-n", str(ranks), sys.executable, str(WORKER), *map(str, args)],
                          cwd=HERE, env=_env(), capture_output=True, text=True, timeout=timeout)


def _ran(proc):
    assert proc.returncode == 0, f"mpiexec failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}"


def _same(a, b):
    """Equal bit for bit: same dtype, shape and bytes."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


# -- one process --------------------------------------------------------------

@pytest.fixture(scope="module")
def single():
    """Every estimator, a work count and the render, in this process."""
    engine = oclgi.Engine(oclgi.load_file(worker.SCENES / "cornell_box.toml"))
    pts = worker.cornell_points(engine)
    out = {m: engine.irradiance(pts, method=m, photons=worker.PHOTONS, radius=worker.RADIUS) for m in worker.METHODS}
    work = engine.irradiance(pts, method="detp_disc_index", photons=worker.PHOTONS, radius=worker.RADIUS,
                             count_work=True).work
    out["work"] = [work[k] for k in worker.WORK_KEYS]
    out["render"] = engine.render(width=worker.VIEW[0], height=worker.VIEW[1], method="detp_disc_index",
                                  photons=worker.PHOTONS, radius=worker.RADIUS)
    out["area"] = engine.irradiance(pts, **worker.AREA)
    ies = oclgi.Engine(oclgi.load_file(worker.SCENES / "cornell_ies.toml"))
    out["gather"] = ies.irradiance(worker.cornell_points(ies), **worker.GATHER)
    return out


@pytest.fixture(scope="module")
def moves(tmp_path_factory):
    path = tmp_path_factory.mktemp("moves") / "moves.npy"
    np.save(path, np.array(_moves(np.random.default_rng(3), N_MOVES)))
    return path


@pytest.fixture(scope="module")
def single_sessions(moves):
    """Each incremental method's session in this process: after the moves, its sums and
    irradiance; the first frame's sums; the paths the moves touched."""
    engine = oclgi.Engine(worker.block_scene())
    out = {}
    for m in worker.INCREMENTAL:
        engine.move("block", np.eye(4))
        s = oclgi.Session(engine, worker.floor_points(), method=m, photons=worker.PHOTONS, radius=worker.SESSION_RADIUS)
        first = s.accumulators()
        touched = sum(s.move("block", mv).paths for mv in np.load(moves))
        out[m] = (s.accumulators(), s.irradiance(), first, touched)
    return out


# -- over 2 and 3 ranks --------------------------------------------------------------

@pytest.mark.parametrize("ranks", RANKS)
def test_every_estimator_equals_one_process(tmp_path, single, ranks):
    _ran(mpiexec(ranks, "irradiance", tmp_path))
    for m in worker.METHODS:
        one = single[m]
        assert np.count_nonzero(one.accumulators) > one.accumulators.size // 2, "the test must reach the points"
        assert _same(np.load(tmp_path / f"{m}_acc.npy"), one.accumulators), m
        assert _same(np.load(tmp_path / f"{m}_irr.npy"), one.irradiance), m
        assert int(np.load(tmp_path / f"{m}_segments.npy")) == one.stats.segments, m
    assert any(single["work"]) and np.load(tmp_path / "work.npy").tolist() == single["work"]
    assert _same(np.load(tmp_path / "render_radiance.npy"), single["render"].radiance)
    assert _same(np.load(tmp_path / "render_pixels.npy"), single["render"].pixels)
    assert _same(np.load(tmp_path / "area_irr.npy"), single["area"].irradiance)  # light samples and MIS
    gather = single["gather"]
    assert len(gather.accumulators) == 8 * len(gather.irradiance) and gather.accumulators.any()
    assert _same(np.load(tmp_path / "gather_acc.npy"), gather.accumulators)
    assert _same(np.load(tmp_path / "gather_irr.npy"), gather.irradiance)


@pytest.mark.parametrize("ranks", RANKS)
def test_session_after_20_moves_equals_one_process(tmp_path, moves, single_sessions, ranks):
    _ran(mpiexec(ranks, "session", tmp_path, moves))
    for m in worker.INCREMENTAL:
        acc, irr, first, touched = single_sessions[m]
        assert touched > 0 and not np.array_equal(acc, first), "the moves must change the sums"
        assert _same(np.load(tmp_path / f"{m}_acc.npy"), acc), m
        assert _same(np.load(tmp_path / f"{m}_irr.npy"), irr), m
        frame_bytes, full_bytes = np.load(tmp_path / f"{m}_bytes.npy")
        assert (frame_bytes <= full_bytes).all(), m
        if m.startswith("detp"):  # a move changes a few of the points' sums: only those travel
            assert 0 < frame_bytes.sum() < full_bytes.sum() / 2, m


def test_session_ranges_add_up_in_one_process(moves):
    """What the ranks of a distributed session hold, without MPI: sessions
    over the parts of the paths sum to the whole session's sums, after moves."""
    engine = oclgi.Engine(worker.block_scene())
    for m in ("detp", "impact"):
        engine.move("block", np.eye(4))
        args = dict(method=m, photons=worker.PHOTONS, radius=worker.SESSION_RADIUS)
        whole = oclgi.Session(engine, worker.floor_points(), **args)
        parts = [oclgi.Session(engine, worker.floor_points(), **args, paths=PathRange(0, worker.PHOTONS).split(3, r))
                 for r in range(3)]
        for mv in np.load(moves)[:5]:
            for s in [whole, *parts]:
                s.move("block", mv)
        assert np.array_equal(sum(s.accumulators() for s in parts), whole.accumulators()), m
        assert sum(len(s.segments()[1]) for s in parts) == worker.PHOTONS


# -- errors -------------------------------------------------------------------------

def _error_lines(proc):
    """The error lines of every rank. A line is one write, but another rank's
    traceback may be written around it (its pieces are separate writes), so
    a line is looked for anywhere, not only at a line's start."""
    return re.findall(r"oclgi: error: [^\n]*", proc.stdout + proc.stderr)


@pytest.mark.parametrize("ranks", RANKS)
@pytest.mark.parametrize("what, message, raised", [
    ("method", "rank 1 of {n}: method: unknown method 'no_such_method'", None),
    ("photons", "rank 1 of {n} was given another scene or other parameters than rank 0", None),
    ("device", "rank 1 of {n}: ", None),  # its Engine finds no such OpenCL device
    # a bug or an interrupt: that rank shows its traceback
    ("bug", "rank 1 of {n}: unexpected RuntimeError: a bug in the run", "RuntimeError: a bug in the run"),
    ("interrupt", "rank 1 of {n}: interrupted", "KeyboardInterrupt"),
])
def test_an_error_on_one_rank_ends_every_rank_with_one_message(tmp_path, what, message, raised, ranks):
    """Rank 0 says which rank failed and how."""
    proc = mpiexec(ranks, "fail", tmp_path, 1, what, timeout=60)
    assert proc.returncode != 0
    # one message (a rank's traceback may be written into its line: compared as a prefix)
    lines = _error_lines(proc)
    assert len(lines) == 1 and lines[0].startswith(f"oclgi: error: {message.format(n=ranks)}"), \
        proc.stdout + proc.stderr
    if raised:
        assert proc.stderr.count("Traceback") == 1 and raised in proc.stderr
    else:
        assert "Traceback" not in proc.stderr
    assert not (tmp_path / "finished.npy").exists()


@pytest.mark.parametrize("ranks", RANKS)
def test_a_failure_inside_an_exchange_aborts_the_job(tmp_path, ranks):
    proc = mpiexec(ranks, "fail", tmp_path, 1, "collective", timeout=60)
    assert proc.returncode != 0
    assert f"oclgi: error: rank 1 of {ranks} failed in an MPI exchange: RuntimeError: an exchange broke" in proc.stderr
    assert not (tmp_path / "finished.npy").exists()


# -- without MPI --------------------------------------------------------------------

def test_one_process_has_no_world_and_never_loads_mpi():
    code = "import sys; from oclgi import distributed; print(distributed.world(), 'mpi4py' in sys.modules)"
    proc = subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["None", "False"]


def test_mpirun_without_mpi4py_names_the_extra(monkeypatch):
    monkeypatch.setenv("PMI_SIZE", "2")
    monkeypatch.setitem(sys.modules, "mpi4py", None)  # as if not installed: importing it fails
    with pytest.raises(oclgi.OclgiError, match=r"one of 2 ranks, but mpi4py is not installed: "
                                                r"pip install 'oclgi\[mpi\]'"):
        distributed.world()


def test_without_a_communicator_it_is_one_process(single, cornell):
    est = distributed.irradiance(cornell, worker.cornell_points(cornell), None, method="detp",
                                 photons=worker.PHOTONS, radius=worker.RADIUS)
    assert _same(est.accumulators, single["detp"].accumulators)


# -- the command line ---------------------------------------------------------

def _oclgi_mpi(ranks, cwd, *args):
    """``oclgi ARGS`` over ``ranks`` MPI ranks (None: in one process, no mpiexec)."""
    launch = [str(MPIEXEC), "-n", str(ranks)] if ranks else []
    return subprocess.run([*launch, sys.executable, "-m", "oclgi", *map(str, args)], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=TIMEOUT)


@pytest.mark.parametrize("ranks", RANKS)
def test_mpirun_oclgi_writes_one_process_bytes(tmp_path, ranks):
    """``mpirun -n K oclgi render|irradiance``: rank 0 writes the files one
    process writes, byte for byte, and says so once."""
    scene = HERE.parent / "scenes" / "cornell_box.toml"
    common = ("--photons", 20_000, "--quiet")
    np.save(tmp_path / "p.npy", np.array([[x, 0.001, 0.8, 0.0, 1.0, 0.0] for x in (-0.5, 0.0, 0.5)]))
    render = ("render", scene, "--width", 16, "--height", 16)
    one = [_oclgi_mpi(None, tmp_path, *render, "-o", "one.exr", *common),
           _oclgi_mpi(None, tmp_path, "irradiance", scene, "--points", "p.npy", "-o", "one.npy", *common)]
    assert all(r.returncode == 0 for r in one), [r.stderr for r in one]
    r = _oclgi_mpi(ranks, tmp_path, *render, "-o", f"r{ranks}.exr", *common)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [f"wrote r{ranks}.exr", f"wrote r{ranks}.png"]
    for suffix in (".exr", ".png"):
        assert (tmp_path / f"one{suffix}").read_bytes() == (tmp_path / f"r{ranks}{suffix}").read_bytes()
    r = _oclgi_mpi(ranks, tmp_path, "irradiance", scene, "--points", "p.npy", "-o", f"e{ranks}.npy", *common)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "one.npy").read_bytes() == (tmp_path / f"e{ranks}.npy").read_bytes()
    # an input error: one line from rank 0, status 2 from the job; a command that does not distribute says so
    r = _oclgi_mpi(ranks, tmp_path, "irradiance", scene, "--points", "missing.npy", "-o", "x.npy")
    assert r.returncode != 0 and r.stderr.strip().splitlines() == ["oclgi: error: points file not found: missing.npy"]
    r = _oclgi_mpi(ranks, tmp_path, "render", scene, "--checkpoint", "c.npz", "-o", "x.exr")
    assert r.returncode != 0 and r.stderr.strip().splitlines() == [
        "oclgi: error: --checkpoint does not run over MPI ranks yet: run it in one process"]
    assert not (tmp_path / "x.exr").exists() and not (tmp_path / "x.npy").exists()


@pytest.mark.full  # make test: the README's mpirun study runs; estimates over ranks equal one process's above
def test_mpirun_oclgi_study_gives_one_process_statistics(tmp_path):
    """The study over 2 ranks: every estimate split over the ranks; the
    statistics (all but the time columns) are one process's."""
    scene = HERE.parent / "scenes" / "cornell_box.toml"
    args = ("study", scene, "--methods", "detp_disc_index,photon_map,impact", "--photons", "1e4,2e4", "--seeds", 2,
            "--points", "random:64", "--reference", "detp:5e4", "--quiet")
    one = _oclgi_mpi(None, tmp_path, *args, "-o", "one")
    assert one.returncode == 0, one.stderr
    two = _oclgi_mpi(2, tmp_path, *args, "-o", "two")
    assert two.returncode == 0, two.stderr
    assert two.stdout.count("wrote ") == one.stdout.count("wrote ") == 4  # rank 0 alone writes

    def rows(folder):
        with open(tmp_path / folder / "study.csv", newline="") as f:
            return [{k: v for k, v in r.items() if k not in ("time_s", "estimate_s", "efficiency")}
                    for r in csv.DictReader(f)]

    assert rows("one") == rows("two") and len(rows("one")) == 6
