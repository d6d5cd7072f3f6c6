"""The one run loop: a range of photon paths traced in batches into one
estimator, resumable, extendable and reducible.

A run of ``photons`` paths is the range of global path ids [0, photons).
``Run`` traces a range (all of it, or a rank's part, :meth:`PathRange.split`)
batch by batch into its estimator. Two facts make its state small and its
results exact however the range is cut (kernels/oclgi_types.h):

- a path's segments depend only on (seed, path id) (kernels/rng.h), never
  on the batch, the range or the run's total;
- photons carry power in units of the largest photon power and the sums are
  64-bit fixed point in units independent of the photon count; ``1/n`` is
  applied only when :meth:`Run.finish` resolves them.

So the state after any batch (:class:`RunState`: the next path and the
estimator's sums) is all a resumed run needs, a run extended by N photons
(:meth:`Run.extend`) equals one run of the longer count, and the integer
sums of disjoint ranges add up to the sums of their union, bit for bit.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .. import interrupt, params as params_mod
from ..errors import OclgiError
from ..cl.programs import read_buffer
from .photon_trace import PhotonTracer

SEGMENT_BYTES = 48  # oclgi/cl/layout.py Segment
ENGINE_STAGES = ("load", "setup")  # Stats.seconds of the engine, not of one run


@dataclass
class Stats:
    photons: int = 0
    segments: int = 0
    points: int = 0
    method: str = ""
    radius: float = 0.0
    seconds: dict = field(default_factory=dict)

    def summary(self) -> str:
        """One line: the run, then the engine's stages (load, setup) and the
        run's (camera, trace, estimate, resolve: they add up to its total)."""
        engine = [f"{k} {v:.2f}s" for k, v in self.seconds.items() if k in ENGINE_STAGES]
        run = [f"{k} {v:.2f}s" for k, v in self.seconds.items() if k not in ENGINE_STAGES]
        return (f"{self.method}: {self.photons:,} photons, {self.segments:,} segments, "
                f"{self.points:,} points, radius {self.radius:.4g} | {' '.join(engine)} | {' '.join(run)}")


@dataclass
class Estimate:
    irradiance: np.ndarray  # (n, 3) float32, W/m^2 per channel
    accumulators: np.ndarray  # int64 fixed-point sums (per point for DETP, per triangle for Impact Count)
    scale: float  # fixed-point units per watt
    stats: Stats
    points: object  # the QueryPoints
    work: dict | None = None  # exact work counts (t, u, nodes) when count_work=True
    estimator: object = None  # the estimator itself (its index, impacts, device buffers), for studies


@dataclass(frozen=True)
class PathRange:
    """Global path ids [first, first + count)."""

    first: int
    count: int

    @property
    def end(self) -> int:
        return self.first + self.count

    def split(self, parts: int, index: int) -> "PathRange":
        """Part ``index`` of ``parts`` contiguous, near-equal parts (the
        first ``count % parts`` one path longer), in order: the parts' ranges
        tile this one."""
        q, r = divmod(self.count, parts)
        return PathRange(self.first + index * q + min(index, r), q + (1 if index < r else 0))


@dataclass
class RunState:
    """Where a run stands: the next path to trace, the segments traced so
    far, and the estimator's sums (``Estimator.state``: int64 accumulators,
    or a Photon Map's impacts)."""

    paths: PathRange
    next_path: int
    segments: int
    sums: dict = field(default_factory=dict)

    @property
    def traced(self) -> int:
        return self.next_path - self.paths.first

    @property
    def done(self) -> bool:
        return self.next_path >= self.paths.end


def batch_paths(batch_bytes: int, max_depth: int, photons: int) -> int:
    """Paths per batch: as many as ``batch_bytes`` of segment slots hold."""
    return max(1, min(photons, batch_bytes // (max_depth * SEGMENT_BYTES)))


class Run:
    """Trace ``paths`` (default: all of [0, params.photons)) in batches into
    ``estimator`` (made by ``engine.estimator`` for ``params``).

    ``step()`` traces one batch; ``state()`` / ``Run.resume`` save and
    restore; ``extend(n)`` adds n photons to the run; ``finish()`` resolves
    the sums of ``params.photons`` paths into an ``Estimate``.
    """

    def __init__(self, engine, estimator, params, paths: PathRange | None = None):
        self.engine, self.estimator, self.params = engine, estimator, params
        self.paths = paths or PathRange(0, params.photons)
        if not (0 <= self.paths.first and self.paths.count >= 0 and self.paths.end <= params.photons):
            raise OclgiError(f"paths {self.paths.first}..{self.paths.end} are not within the run's "
                             f"{params.photons:,} photons")
        self.next_path = self.paths.first
        self.segments = 0
        self.marks = None  # batches end on multiples of this many paths (progressive images)
        self.camera, self.spp = None, 1  # a render run's view (Engine.render_run)
        self.seconds = {"trace": 0.0, "estimate": 0.0}
        self.checked = False  # the estimator has checked the run from its first batch (step)
        self.set_batch(batch_paths(engine.batch_bytes, params.max_depth, max(1, self.paths.count)))

    def set_batch(self, paths: int) -> None:
        """Trace ``paths`` paths per batch from now on (results do not
        depend on it; saves, progress and progressive images come between
        batches)."""
        self.batch = params_mod.photons(paths, "paths per batch")
        limit = self.engine.queue.device.max_mem_alloc_size
        if self.batch * self.params.max_depth * SEGMENT_BYTES > limit:
            raise OclgiError(f"{self.batch:,} paths of up to {self.params.max_depth} segments per batch need more "
                             f"than one device buffer holds ({limit / 2**30:.2f} GiB); give fewer")
        self.tracer = PhotonTracer(self.engine.queue, self.engine.compiled, self.params.seed, self.params.max_depth,
                                   self.batch, self.engine.local_size)
        self._lens = np.empty(self.batch, np.int32)

    # -- stepping -----------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.next_path >= self.paths.end

    @property
    def traced(self) -> int:
        """Paths of the range traced so far."""
        return self.next_path - self.paths.first

    def step(self) -> int:
        """Trace and accumulate the next batch; returns its number of paths
        (0 once the range is done)."""
        n = min(self.batch, self.paths.end - self.next_path)
        if self.marks:
            n = min(n, self.marks - self.traced % self.marks)
        if n <= 0:
            return 0
        queue = self.engine.queue
        ta = time.perf_counter()
        batch = self.tracer.trace(self.next_path, n)
        cl.enqueue_copy(queue, self._lens[:n], batch.path_len)  # also waits for the trace
        tb = time.perf_counter()
        self.estimator.accumulate(batch)
        queue.finish()
        tc = time.perf_counter()
        self.segments += int(self._lens[:n].sum())
        self.next_path += n
        self.seconds["trace"] += tb - ta
        self.seconds["estimate"] += tc - tb
        if not self.checked:  # the estimator's own check of the run (a Photon Map outgrowing the device)
            self.checked = True
            self.estimator.first_batch(self.traced, self.paths.count, self.segments)
        return n

    # -- state ----------------------------------------------------------------
    def state(self) -> RunState:
        """The run's state now (a copy on the host)."""
        return RunState(self.paths, self.next_path, self.segments, self.estimator.state())

    @classmethod
    def resume(cls, engine, estimator, params, state: RunState) -> "Run":
        """A run that goes on from ``state`` (taken from a run of the same
        scene and parameters, over the same points)."""
        run = cls(engine, estimator, params, state.paths)
        run.restore(state)
        return run

    def restore(self, state: RunState) -> None:
        """Go on from ``state``, a state of this run's range (``state()``
        of a run of the same scene, parameters and points)."""
        if state.paths != self.paths:
            raise OclgiError(f"run state: paths {state.paths.first}..{state.paths.end}, this run's are "
                             f"{self.paths.first}..{self.paths.end}")
        if not self.paths.first <= state.next_path <= self.paths.end or state.segments < 0:
            raise OclgiError(f"run state: next path {state.next_path} is outside paths "
                             f"{self.paths.first}..{self.paths.end}")
        self.estimator.restore(state.sums)
        self.next_path, self.segments = int(state.next_path), int(state.segments)

    def extend(self, photons: int) -> None:
        """Add ``photons`` paths to the run (and to its range, which must end
        where the run does): the result of the longer run equals one run of
        the total count, bit for bit."""
        photons = params_mod.photons(photons, "more photons")
        if self.paths.end != self.params.photons:
            raise OclgiError("only a run whose range ends at its last photon can be extended")
        total = self.params.photons + photons
        params_mod.photons(total, "photons (the run's and the added ones)")
        self.params = dataclasses.replace(self.params, photons=total)
        self.paths = PathRange(self.paths.first, self.paths.count + photons)
        self.estimator.extended(total)

    def complete(self, progress: bool | None = None, on_batch=None):
        """``trace`` to the end of the range, then ``finish()``."""
        t0 = time.perf_counter()
        self.trace(progress, on_batch)
        est = self.finish()
        # the run's stages (camera points, made with the run, to resolve): load and setup are the engine's
        est.stats.seconds["total"] = time.perf_counter() - t0 + self.seconds.get("camera", 0.0)
        return est

    def trace(self, progress: bool | None = None, on_batch=None, notice: bool = True) -> None:
        """Step to the end of the range, with a progress bar (``progress``
        as ``oclgi.progress.Progress`` takes it) and, after each batch,
        ``on_batch(self)`` (e.g. a checkpoint). After the first batch (which
        the estimator checks, ``step``), with ``notice``, a run estimated to
        take over a minute says so."""
        from .. import budget
        from ..progress import Progress
        from ..scene.scene import OclgiWarning

        t0 = time.perf_counter()
        bar = Progress(self.params.method, self.paths.count, progress)
        bar.update(self.traced)
        first = True
        try:
            while not self.done:
                interrupt.reraise_swallowed()  # a Ctrl-C a library swallowed still stops the run
                n = self.step()
                bar.update(n)
                if first:  # a long run says so, with its time from the first batch
                    first = False
                    line = budget.time_notice(n, time.perf_counter() - t0, self.paths.end - self.next_path + n)
                    if line and notice:
                        warnings.warn(line, OclgiWarning, stacklevel=4)
                if on_batch is not None:
                    on_batch(self)
        finally:
            bar.close()

    # -- result ---------------------------------------------------------------
    def finish(self, photons: int | None = None):
        """The estimate from the sums of ``photons`` paths (default: the
        run's count; a partial result, e.g. a progressive image, passes the
        paths traced so far)."""
        n = self.params.photons if photons is None else int(photons)
        if n <= 0:
            raise OclgiError("no photons traced yet")
        est = self.estimator
        scale = self.engine.compiled.fixed_scale(n)
        t0 = time.perf_counter()
        irr = read_buffer(self.engine.queue, est.resolve(scale), (est.n, 4), np.float32)
        resolve = time.perf_counter() - t0  # a Photon Map's k-nearest search is here
        p = self.params
        stats = Stats(photons=n, segments=self.segments, points=est.n, method=p.method, radius=float(p.radius))
        # the engine's own stages (reading the scene, building its trees), then the run's
        stats.seconds = {"load": self.engine.scene.load_seconds, "setup": self.engine.setup_seconds,
                         **{k: self.seconds[k] for k in ("camera", "trace", "estimate") if k in self.seconds},
                         "resolve": resolve}
        return Estimate(irr[:, :3], est.accumulators(), scale, stats, est.points, est.work(), est)
