"""One run over many processes (MPI ranks), equal bit for bit to one process.

Start a program under ``mpirun -n K`` (or ``mpiexec``); :func:`world` gives
its communicator (None in a plain process, which then never imports mpi4py).
The calls below are collective: every rank makes them, in the same order,
with the same arguments (the query points, the camera and a session's moves
are taken from rank 0 and broadcast, so other ranks may pass None).

- :func:`irradiance` and :func:`render` split the run's path ids [0, photons)
  into K contiguous ranges (``PathRange.split``), one per rank, each traced on
  the rank's own OpenCL device. The sums of disjoint ranges add up exactly
  (int64 fixed point, kernels/oclgi_types.h), so an integer ``MPI.Reduce``
  of the accumulators onto rank 0 gives the single-process sums, and rank 0
  resolves them with the run's total photon count. A Photon Map's impacts
  are gathered onto rank 0 in rank order, which is path order: its
  k-nearest search sees exactly the impacts of one process.
- :class:`Session` is the incremental session with each rank storing and
  updating its own range of paths; after each move only the accumulator
  rows a rank's move changed travel to rank 0 (row id and delta).

The scene: every rank builds its own Engine. :func:`load_scene` loads the
scene on rank 0 and broadcasts it (other ranks need no access to its files),
:func:`engine` also builds each rank's Engine; a program may instead load the
same file on every rank. Either way the ranks' compiled scenes are compared
(``CompiledScene.fingerprint``), and the run's parameters too: a difference
is an error before any work. :func:`on_root` and :func:`everywhere` run any
other step (reading points on rank 0, say) with its errors agreed.

A program (``mpirun -n 4 python render.py``)::

    comm = distributed.world()                      # None in a plain process
    engine = distributed.engine(comm, "scenes/cornell_box.toml") if comm else oclgi.Engine(...)
    result = distributed.render(engine, comm, photons=10**8)
    if distributed.is_root(comm):                   # rank 0 writes the outputs
        oclgi.save_render(result, "out/cornell_box.exr")

Errors: every phase ends in an exchange of each rank's outcome (an
allgather of an error message or None), so an error on any rank ends every
rank with the same message: rank 0 raises OclgiError, the other ranks raise
:class:`PeerError` (an OclgiError a command line exits on without printing,
so the message is printed once). An exception that is not an OclgiError (a
bug, Ctrl-C) is also exchanged, then re-raised on its rank as it was. What
fails inside a collective call itself aborts the whole job (``comm.Abort``),
the one way out that cannot hang. A rank that stops responding (a device
that hangs) still holds the others in the next exchange, as in any MPI job.
"""

from __future__ import annotations

import os
import sys
import time
from contextlib import contextmanager

import numpy as np

from .errors import OclgiError

# Set by the launchers in every rank: MPICH's and Intel MPI's hydra (PMI),
# Open MPI. Read before mpi4py is imported, so that a plain process never
# loads (or initialises) MPI.
SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE")
INSTALL = "pip install 'oclgi[mpi]'"


class PeerError(OclgiError):
    """The error another rank met (or rank 0 reports): raised on every rank
    but 0 with the same message, which rank 0 prints."""


def launched_size() -> int:
    """The number of ranks the launcher started (1 for a plain process)."""
    size = 1
    for var in SIZE_VARIABLES:
        try:
            size = max(size, int(os.environ.get(var, "1")))
        except ValueError:
            pass
    return size


RANK_VARIABLES = ("PMI_RANK", "OMPI_COMM_WORLD_RANK")


def launched_rank() -> int:
    """This process's rank as the launcher set it (0 for a plain process)."""
    for var in RANK_VARIABLES:
        try:
            return int(os.environ[var])
        except (KeyError, ValueError):
            pass
    return 0


def world():
    """MPI's world communicator when this process is one of several ranks
    started by mpirun/mpiexec, else None."""
    size = launched_size()
    if size <= 1:
        return None
    try:
        from mpi4py import MPI
    except ImportError:
        raise OclgiError(f"started by mpirun as one of {size} ranks, but mpi4py is not installed: "
                         f"{INSTALL}") from None
    comm = MPI.COMM_WORLD
    if comm.size != size:
        # mpi4py linked to another MPI than the launcher's: each process would
        # think itself alone and compute (and write) the whole run
        raise OclgiError(f"mpirun started {size} ranks but mpi4py's MPI sees {comm.size}: mpirun and "
                         f"mpi4py come from different MPI libraries; use the mpiexec of the MPI mpi4py uses")
    return comm


def is_root(comm) -> bool:
    """Whether this process writes the outputs: rank 0, or a plain process."""
    return comm is None or comm.rank == 0


# -- agreeing on errors --------------------------------------------------------


def _abort(comm, exc: BaseException):
    """The last resort: a failure inside a collective call leaves the other
    ranks waiting in it, so the whole job is ended."""
    print(f"oclgi: error: rank {comm.rank} of {comm.size} failed in an MPI exchange: "
          f"{type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
    comm.Abort(3)


def _agree(comm, error: str | None):
    """Every rank's outcome of a phase: raises on every rank when any failed,
    with the message of the first rank that did."""
    try:
        errors = comm.allgather(error)
    except Exception as exc:  # noqa: BLE001 - any failure here would hang the others
        _abort(comm, exc)
        raise
    for r, e in enumerate(errors):
        if e is not None:
            msg = e if r == 0 else f"rank {r} of {comm.size}: {e}"
            raise (OclgiError if comm.rank == 0 else PeerError)(msg)


@contextmanager
def _phase(comm):
    """Local work of every rank, then the exchange of outcomes."""
    unexpected = error = None
    try:
        yield
    except OclgiError as exc:  # a PeerError too: an inner phase already agreed; say it once more
        error = str(exc)
    except KeyboardInterrupt as exc:  # Ctrl-C (mpiexec passes it to every rank)
        unexpected, error = exc, "interrupted"
    except BaseException as exc:  # noqa: BLE001 - a bug, or an exit: still end every rank, then go on here
        unexpected, error = exc, f"unexpected {type(exc).__name__}: {exc}"
    try:
        _agree(comm, error)
    except OclgiError:
        if unexpected is not None:
            raise unexpected from None  # its own traceback, not the exchange's
        raise


@contextmanager
def _collective(comm):
    """Collective MPI calls, which every rank has agreed to enter."""
    try:
        yield
    except Exception as exc:  # noqa: BLE001
        _abort(comm, exc)
        raise


def share(comm, value):
    """Rank 0's value on every rank (pickled)."""
    with _collective(comm):
        return comm.bcast(value, root=0)


def on_root(comm, make, *args, **kwargs):
    """``make(*args, **kwargs)`` called on rank 0 only (e.g. reading a file
    of points only rank 0 can see), its value broadcast to every rank; an
    error in it ends every rank (as every call here)."""
    value = None
    with _phase(comm):
        if comm.rank == 0:
            value = make(*args, **kwargs)
    return share(comm, value)


def everywhere(comm, make, *args, **kwargs):
    """``make(*args, **kwargs)`` on every rank, its errors agreed: what may
    fail on one rank only (e.g. ``oclgi.Engine``, which opens the rank's
    OpenCL device) without leaving the others waiting."""
    value = None
    with _phase(comm):
        value = make(*args, **kwargs)
    return value


def load_scene(comm, path):
    """The scene file ``path`` loaded on rank 0 and broadcast (the other
    ranks may pass None and need no access to its files)."""
    from .scene.description import load_file

    return on_root(comm, load_file, path)


def engine(comm, path, **engine_args):
    """An Engine on every rank for the scene file ``path`` (rank 0's,
    loaded there and broadcast); ``engine_args`` as oclgi.Engine takes them."""
    from .engine import Engine

    return everywhere(comm, Engine, load_scene(comm, path), **engine_args)


def _check_same(comm, engine, what: str, key: str):
    """The ranks agree on ``key`` (the compiled scene's fingerprint and the run's parameters)."""
    keys = None
    with _phase(comm):
        mine = f"{engine.compiled.fingerprint()}|{key}"
    with _collective(comm):
        keys = comm.allgather(mine)
    with _phase(comm):
        differ = [r for r, k in enumerate(keys) if k != keys[0]]
        if differ:
            raise OclgiError(f"rank {differ[0]} of {comm.size} was given another scene or other {what} than rank 0")


# -- one run over the ranks ------------------------------------------------------


def _reduce_state(comm, state: dict) -> dict | None:
    """The ranks' estimator states combined on rank 0 (None elsewhere):
    integer arrays summed, a Photon Map's impacts concatenated in rank order."""
    from mpi4py import MPI

    out = {}
    for key, a in sorted(state.items()):
        a = np.ascontiguousarray(a)
        if a.dtype.kind in "iu":
            recv = np.empty_like(a) if comm.rank == 0 else None
            comm.Reduce(a, recv, op=MPI.SUM, root=0)
        else:
            rows = comm.gather(a.shape[0], root=0)
            recv = None
            if comm.rank == 0:
                recv = np.empty((sum(rows), *a.shape[1:]), a.dtype)
                per_row = int(np.prod(a.shape[1:], dtype=np.int64))
                comm.Gatherv(a, (recv, [r * per_row for r in rows]), root=0)
            else:
                comm.Gatherv(a, None, root=0)
        out[key] = recv
    return out if comm.rank == 0 else None


def irradiance(engine, points, comm, method: str | None = None, photons: int | None = None,
               radius: float | None = None, seed: int | None = None, max_depth: int | None = None,
               extension: float | None = None, count_emitted: bool | None = None, count_work: bool = False,
               progress: bool | None = None, **options):
    """``engine.irradiance`` over the ranks of ``comm``: the Estimate on rank
    0 (equal bit for bit to one process's), None on the others. ``points``
    are rank 0's (broadcast). ``comm`` None: one process, ``engine.irradiance``.
    ``progress`` (default: the engine's) is shown by rank 0 only, for its
    own part of the paths."""
    args = dict(method=method, photons=photons, radius=radius, seed=seed, max_depth=max_depth,
                extension=extension, count_emitted=count_emitted)
    if comm is None:
        return engine.irradiance(points, count_work=count_work, **args, **options)
    return _Distributed(engine, comm, args, count_work, options).irradiance(points, progress)


class _Distributed:
    def __init__(self, engine, comm, args, count_work, options):
        self.engine, self.comm, self.args, self.count_work, self.options = engine, comm, args, count_work, options

    def params(self):
        params = None
        with _phase(self.comm):
            params = self.engine.run_params(**self.args)
        _check_same(self.comm, self.engine, "parameters",
                    repr((params, bool(self.count_work), sorted(self.options.items()))))
        return params

    def irradiance(self, points, progress):
        from .tracing.run import PathRange

        comm, engine = self.comm, self.engine
        t0 = time.perf_counter()
        points = share(comm, points)
        params = self.params()
        run = None
        with _phase(comm):
            part = PathRange(0, params.photons).split(comm.size, comm.rank)
            run = engine.run(points, **self.args, count_work=self.count_work, paths=part, **self.options)
        with _phase(comm):
            shown = engine.progress if progress is None else progress  # as Engine.irradiance shows it
            run.trace(shown if comm.rank == 0 else False, notice=comm.rank == 0)
        t1 = time.perf_counter()
        state = None
        with _phase(comm):
            state = run.estimator.state()
        with _collective(comm):
            total = _reduce_state(comm, state)
            segments = comm.reduce(run.segments, root=0)
        est = None
        with _phase(comm):
            if comm.rank == 0:
                run.estimator.restore(total)
                run.segments = segments
                run.next_path = run.paths.end
                run.seconds["reduce"] = time.perf_counter() - t1
                est = run.finish()
                est.stats.seconds["total"] = time.perf_counter() - t0
        return est


class EveryRank:
    """An Engine (its attributes are the wrapped one's) whose ``irradiance``
    runs over the ranks of ``comm`` and returns the estimate on every rank:
    rank 0's irradiance, sums, scale, stats and work counts, broadcast. For
    programs that every rank runs alike and that look at every estimate,
    such as the estimator study (``mpirun -n K oclgi study``); the ranks'
    estimates carry no estimator (its device buffers stay on rank 0)."""

    def __init__(self, engine, comm):
        self._engine, self._comm = engine, comm

    def __getattr__(self, name):
        return getattr(self._engine, name)

    def irradiance(self, points, count_work: bool = False, **kwargs):
        from .tracing.run import Estimate

        est = irradiance(self._engine, points, self._comm, count_work=count_work, **kwargs)
        shared = share(self._comm, None if est is None else
                       (est.irradiance, est.accumulators, est.scale, est.stats, est.work, est.points))
        if est is not None:
            return est
        irr, acc, scale, stats, work, pts = shared
        return Estimate(irr, acc, scale, stats, pts, work, None)


def render(engine, comm, camera=None, width: int | None = None, height: int | None = None,
           exposure: float = 1.0, spp: int = 1, view: str = "srgb", **estimate_args):
    """``engine.render`` over the ranks of ``comm``: the Render on rank 0,
    None on the others (rank 0's camera and sizes are used). ``comm`` None:
    one process."""
    from . import params
    from .engine import Render, render_metadata

    if comm is None:
        return engine.render(camera, width, height, exposure, spp=spp, view=view, **estimate_args)
    t0 = time.perf_counter()
    pts = None
    with _phase(comm):
        if comm.rank == 0:
            exposure = params.exposure(exposure, "exposure")
            view = params.view(view)
            r = engine.run_params(*(estimate_args.get(k) for k in params.RUN_KEYS))
            cam, spp, pts = engine.render_points(camera, width, height, spp, estimate_args)
    t_cam = time.perf_counter() - t0
    est = irradiance(engine, pts, comm, **estimate_args)
    result = None
    with _phase(comm):
        if comm.rank == 0:
            radiance, pixels = engine.shade(est.points, est.estimator.irr, exposure, spp, view)  # resolved by finish
            est.stats.seconds = {"camera": t_cam, **est.stats.seconds, "total": time.perf_counter() - t0}
            result = Render(radiance, pixels, est, render_metadata(engine, r, est, cam, spp, exposure, view))
    return result


# -- incremental sessions over the ranks -----------------------------------------


class Session:
    """An incremental DETP or Impact Count session (oclgi.Session) over the
    ranks of ``comm``: each rank traces, stores and updates its own range of
    the paths; rank 0 keeps the sums of all of them.

    ``points``: fixed query points (rank 0's, broadcast); the other arguments
    as for oclgi.Session. ``move`` is collective and applies rank 0's move on
    every rank. After each move every rank sends rank 0 only the rows of its
    accumulators that the move changed (row id and int64 delta), which rank 0
    adds to its totals, or, when most rows changed, a Reduce of every row's
    delta: ``frame_bytes`` (rank 0) says how many bytes the other ranks sent
    for the last move, ``full_bytes`` what a Reduce of every row sends.
    ``accumulators()`` and ``irradiance()`` answer on rank 0 (None
    elsewhere), equal bit for bit to a one-process session's.
    """

    def __init__(self, engine, points, comm, method=None, photons=None, radius=None, seed=None, max_depth=None,
                 extension=None, count_emitted=None, count_work=False, **options):
        from .incremental.session import Session as LocalSession
        from .tracing.run import PathRange

        self.engine, self.comm = engine, comm
        points = share(comm, points)
        args = dict(method=method, photons=photons, radius=radius, seed=seed, max_depth=max_depth,
                    extension=extension, count_emitted=count_emitted)
        self.local = None
        with _phase(comm):
            if points is None:
                raise OclgiError("a distributed session takes fixed query points (an (n, 6) array or "
                                 "QueryPoints), not a camera view")
            params = engine.run_params(**args)
            if params.photons < comm.size:
                raise OclgiError(f"{params.photons:,} photons for {comm.size} ranks: a session needs at least "
                                 "one path per rank")
        _check_same(comm, engine, "parameters", repr((params, bool(count_work), sorted(options.items()))))
        with _phase(comm):
            self.paths = PathRange(0, params.photons).split(comm.size, comm.rank)
            self.local = LocalSession(engine, points, **args, count_work=count_work, paths=self.paths, **options)
            self.params = self.local.params
            self.scale = engine.compiled.fixed_scale(params.photons)  # the total's, as one process's
            self.last = self.local.accumulators()
            self.resolver = None
            if comm.rank == 0:
                # resolves the totals (the local estimator keeps rank 0's own sums)
                self.resolver = engine.estimator(self.local.points, self.params, **self.local.options)
        with _collective(comm):
            state = _reduce_state(comm, {"acc": self.last})
        self.total = None if state is None else state["acc"]
        # what the other ranks send rank 0 per move: their changed rows, or
        # for a Reduce of every row, full_bytes
        self.frame_rows = self.frame_bytes = 0
        self.full_bytes = self.last.nbytes * (comm.size - 1)

    def move(self, name: str, matrix):
        """Place object ``name`` (rank 0's name and matrix) on every rank and
        update: the rank's UpdateStats, with ``seconds['reduce']``; rank 0's
        ``frame_rows`` and ``frame_bytes`` say what the reduction moved."""
        comm = self.comm
        name, matrix = share(comm, (name, matrix))
        stats = None
        with _phase(comm):
            stats = self.local.move(name, matrix)
        t0 = time.perf_counter()
        acc = rows = None
        with _phase(comm):
            acc = self.local.accumulators()
            rows = np.nonzero((acc != self.last).any(axis=1))[0].astype(np.int64)
        with _collective(comm):
            self._reduce_changes(acc, rows)
        self.last = acc
        stats.seconds["reduce"] = time.perf_counter() - t0
        return stats

    def _reduce_changes(self, acc, rows):
        """Add every rank's change of its sums to rank 0's totals: the changed
        rows (id and delta, gathered in rank order), or a Reduce of every
        row's delta when that sends fewer bytes (every rank knows the counts,
        so all make the same choice)."""
        from mpi4py import MPI

        comm = self.comm
        counts = comm.allgather(len(rows))
        row_bytes = 8 + acc.itemsize * acc.shape[1]  # an int64 row id and the row's deltas
        sparse = sum(counts[1:]) * row_bytes
        if sparse > self.full_bytes:
            delta = acc - self.last  # int64, wrapping as the device's sums do
            recv = np.empty_like(delta) if comm.rank == 0 else None
            comm.Reduce(delta, recv, op=MPI.SUM, root=0)
            if comm.rank == 0:
                self.total += recv
            self.frame_rows, self.frame_bytes = acc.shape[0], self.full_bytes
            return
        delta = np.ascontiguousarray(acc[rows] - self.last[rows])
        width = acc.shape[1]
        if comm.rank != 0:
            comm.Gatherv(rows, None, root=0)
            comm.Gatherv(delta, None, root=0)
            return
        all_rows = np.empty(sum(counts), np.int64)
        all_delta = np.empty((sum(counts), width), np.int64)
        comm.Gatherv(rows, (all_rows, counts), root=0)
        comm.Gatherv(delta, (all_delta, [c * width for c in counts]), root=0)
        np.add.at(self.total, all_rows, all_delta)
        self.frame_rows, self.frame_bytes = len(all_rows), sparse

    def accumulators(self):
        """The sums of all ranks' paths (rank 0; None elsewhere)."""
        return None if self.total is None else self.total.copy()

    def irradiance(self):
        """(n, 3) irradiance from the sums of all ranks (rank 0; None elsewhere)."""
        out = None
        with _phase(self.comm):
            if self.comm.rank == 0:
                from .cl.programs import read_buffer

                est = self.resolver
                est.restore({"acc": self.total, "work": np.zeros(3, np.uint64)})
                out = read_buffer(self.engine.queue, est.resolve(self.scale), (est.n, 4), np.float32)[:, :3]
        return out

