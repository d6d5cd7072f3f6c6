"""Interactive sessions: illumination kept up to date as objects move.

A session traces every photon path once and keeps all segments on the
device (path-major, DESIGN.md section 2). After ``move(name, matrix)`` only
the paths the move touches change (DESIGN.md section 4, García 2004/2007):

1. ``update_first_affected`` finds, per path, the first segment that hit the
   object at its old pose or meets it at its new pose;
2. the affected suffixes are gathered with negated power and accumulated
   (their old contributions leave the sums exactly);
3. the suffixes are re-traced in place (``photon_retrace``: the same code
   and random numbers as a full trace);
4. the new suffixes are gathered and accumulated.

Sums are fixed point, so the result equals a recomputation from scratch at
the new pose bit for bit, however many moves came before: errors never
accumulate. Query points are either fixed (sensors: an array of points and
normals) or the visible points of a camera (``points=None``, see
oclgi/dynamic_view.py): pixels on static surfaces are updated like fixed
points, pixels on a movable object are the thesis' "dynamic points", their
sums recomputed from the whole store after each move (by ``dynamic``, a
DETP variant: disc indexing by default, the sphere cache as the thesis
has it), and ``render()`` shades the current view.

    >>> import numpy as np, oclgi
    >>> scene = oclgi.load_file(oclgi.scene_path("cornell_box.toml"))
    >>> session = oclgi.Session(oclgi.Engine(scene), np.array([[0, 0.01, 0, 0, 1, 0]]), photons=5000)
    >>> session.irradiance().shape
    (1, 3)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .cl.layout import Segment
from .cl.programs import launch, programs
from .engine import as_query_points
from .errors import OclgiError
from .photon_trace import PathBatch, PhotonTracer
from .queries import QueryPoints


@dataclass
class UpdateStats:
    paths: int  # paths re-traced
    segments_removed: int  # old suffix segments taken away (n_Rec)
    segments_added: int  # new suffix segments added
    points: int = 0  # dynamic points recomputed (camera sessions)
    seconds: dict = field(default_factory=dict)


def _copy(q: QueryPoints) -> QueryPoints:
    return QueryPoints(q.positions.copy(), q.normals.copy(), q.barys.copy(), q.kind, q.shape)


def _add_work(total: dict | None, more: dict | None) -> dict | None:
    if total is None or more is None:
        return total or more
    return {k: total[k] + more[k] for k in total}


class Session:
    """A scene, an estimator and query points, kept up to date under moves.

    ``points``: QueryPoints or an (n, 6) array (x y z nx ny nz); the other
    arguments as for :meth:`oclgi.Engine.irradiance`; ``dynamic``: the DETP
    variant that recomputes a camera session's dynamic points (default
    ``detp_disc_index``). Every segment of every path stays on the device:
    memory is photons x max_depth x 48 bytes.
    """

    fuse_find = True  # False: dynamic points summed over the new store in a pass of their own (benchmarks)

    def __init__(self, engine, points=None, method=None, photons=None, radius=None, seed=None, max_depth=None,
                 extension=None, count_emitted=None, count_work=False, camera=None, dynamic=None, **options):
        from .estimators import ESTIMATORS

        self.engine = engine
        self.queue = engine.queue
        self.camera = camera
        self.options = dict(options, count_work=count_work)
        self.params = engine.run_params(method, photons, radius, seed, max_depth, extension, count_emitted)
        p = self.params
        cls = ESTIMATORS[p.method]
        if not cls.incremental:
            raise OclgiError(f"method {p.method!r} has no exact incremental update; sessions take "
                             f"{', '.join(m for m, c in ESTIMATORS.items() if c.incremental)}")
        self.view = None
        if points is None:
            from .dynamic_view import DynamicView

            self.view = DynamicView(engine, camera)
            self.points = self.view.points  # the composite view, kept current by the view
            # DETP keeps sums per point: the estimator holds the static layer
            # for good; Impact Count keeps sums per triangle and just shades
            # whichever point each pixel sees.
            est_points = self.view.static if cls.sums_per_point else _copy(self.view.points)
        else:
            self.points = _copy(as_query_points(points))
            est_points = self.points
        detp_variants = [m for m in ESTIMATORS if m.startswith("detp")]
        self.dynamic = dynamic or ("detp_disc_index" if p.method.startswith("detp") else p.method)
        if self.dynamic not in detp_variants and (cls.sums_per_point or dynamic is not None):
            raise OclgiError(f"dynamic points are recomputed by a DETP variant ({', '.join(detp_variants)}), "
                             f"got {self.dynamic!r}")
        store_bytes = p.photons * p.max_depth * Segment.itemsize
        limit = engine.queue.device.max_mem_alloc_size
        if store_bytes > limit:
            raise OclgiError(f"a session keeps every segment: {p.photons:,} paths x {p.max_depth} slots need "
                             f"{store_bytes / 2**30:.2f} GiB, more than one device allocation "
                             f"({limit / 2**30:.2f} GiB); use fewer photons or a smaller max_depth")
        self.store_bytes = store_bytes
        self.scale = engine.compiled.fixed_scale(p.photons)
        self.estimator = engine.estimator(est_points, p, **self.options)
        self.tracer = PhotonTracer(self.queue, engine.compiled, p.seed, p.max_depth, p.photons, engine.local_size)
        t0 = time.perf_counter()
        self.store = self.tracer.trace(0, p.photons, p.photons)
        self.estimator.accumulate(self.store, self.scale)
        self.dyn_est, self.dyn_index, self.dynamic_work = None, np.zeros(0, np.int64), None
        if self.view is not None and cls.sums_per_point:
            self._new_dynamic()
            if self.dyn_est is not None:
                self.dyn_est.accumulate(self.store, self.scale)
                self.dynamic_work = self.dyn_est.work()
        self.queue.finish()
        self.setup_seconds = time.perf_counter() - t0
        prog = programs(engine.ctx).get("update")
        self.k_first, self.k_gather = prog.update_first_affected, prog.update_gather
        mf = cl.mem_flags
        self.first = cl.Buffer(engine.ctx, mf.READ_WRITE, p.photons * 4)
        self.first_host = np.empty(p.photons, np.int32)
        self.scratch = None  # grown on demand: gathered suffixes

    # -- reading ------------------------------------------------------------
    def _irradiance4(self) -> np.ndarray:
        buf = self.estimator.resolve(self.scale)
        out = np.empty((len(self.points), 4), np.float32)
        cl.enqueue_copy(self.queue, out, buf)
        if self.dyn_est is not None:
            dyn = np.empty((len(self.dyn_index), 4), np.float32)
            cl.enqueue_copy(self.queue, dyn, self.dyn_est.resolve(self.scale))
            out[self.dyn_index] = dyn
        return out

    def irradiance(self) -> np.ndarray:
        """(n, 3) irradiance at the query points (the pixels' current visible points), W/m^2."""
        return self._irradiance4()[:, :3]

    def accumulators(self) -> np.ndarray:
        """The exact fixed-point sums behind the irradiance."""
        acc = self.estimator.accumulators()
        if self.dyn_est is not None:
            acc[self.dyn_index] = self.dyn_est.accumulators()
        return acc

    def work(self) -> dict | None:
        """Exact work counts so far (count_work=True), dynamic points included."""
        return _add_work(self.estimator.work(), self.dynamic_work)

    def segments(self) -> tuple[np.ndarray, np.ndarray]:
        """The stored segments (path-major) and path lengths, on the host."""
        return self.store.read_segments(self.queue), self.store.read_path_len(self.queue)

    def render(self, exposure: float = 1.0):
        """(radiance (H, W, 3), tone-mapped pixels (H, W, 4)) of the camera view."""
        if self.points.kind != "camera":
            raise OclgiError("render() needs a camera session (points=None)")
        irr = self._irradiance4()
        buf = cl.Buffer(self.engine.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=irr)
        return self.engine.shade(self.points, buf, exposure)

    # -- moving -----------------------------------------------------------------
    def move(self, name: str, matrix) -> UpdateStats:
        """Place object ``name`` (4x4 world-from-object matrix) and update."""
        engine, p, q = self.engine, self.params, self.queue
        obj = engine.scene.object_id(name)
        t0 = time.perf_counter()
        engine.move(name, matrix)
        seconds = {}
        n_view = self._refresh_view() if self.view is not None else 0
        t1 = time.perf_counter()
        if self.view is not None:
            seconds["points"] = t1 - t0
        # A disc-indexed dynamic estimator takes its sums over the old store
        # in the find pass; the suffix passes below then update them as they
        # update the static points (update.cl). Any other variant sums over
        # the new store at the end.
        fused = self.fuse_find and self.dyn_est is not None and self.dynamic == "detp_disc_index"
        paths, starts = self._find(obj, self.dyn_est if fused else None)
        t2 = time.perf_counter()
        seconds["find"] = t2 - t1
        stats = UpdateStats(paths=len(paths), segments_removed=0, segments_added=0, points=n_view)
        estimators = [self.estimator] + ([self.dyn_est] if fused else [])
        if len(paths):
            lens = self.store.read_path_len(q)[paths]
            stats.segments_removed = int((lens - starts).sum())
            mf = cl.mem_flags
            paths_buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=paths)
            starts_buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=starts)
            self._accumulate_suffixes(paths_buf, starts_buf, len(paths), -1.0, estimators)
            q.finish()  # honest per-stage times
            t3 = time.perf_counter()
            self.tracer.retrace(self.store, p.photons, paths_buf, starts_buf, len(paths))
            q.finish()
            t4 = time.perf_counter()
            self._accumulate_suffixes(paths_buf, starts_buf, len(paths), 1.0, estimators)
            q.finish()
            stats.segments_added = int((self.store.read_path_len(q)[paths] - starts).sum())
            t5 = time.perf_counter()
            seconds.update(subtract=t3 - t2, retrace=t4 - t3, add=t5 - t4)
        if self.dyn_est is not None and not fused:
            t6 = time.perf_counter()
            self.dyn_est.accumulate(self.store, self.scale)
            q.finish()
            seconds["points"] += time.perf_counter() - t6
        if self.dyn_est is not None:
            self.dynamic_work = _add_work(self.dynamic_work, self.dyn_est.work())
        seconds["total"] = time.perf_counter() - t0
        stats.seconds = seconds
        return stats

    def _find(self, obj: int, discs=None):
        """Paths touched by object ``obj``'s move and their first affected
        bounce (host arrays); with ``discs`` (a DetpDiscIndex) the same pass
        also sums the store into its points."""
        engine, p, q = self.engine, self.params, self.queue
        args = (*engine.compiled.scene_args, np.int32(obj), self.store.segments, np.int32(p.photons),
                np.int32(p.max_depth), self.first)
        if discs is None or discs.nodes is None:
            launch(q, self.k_first, p.photons, *args, local_size=engine.local_size)
        else:
            k = programs(engine.ctx).get("update", **discs.defines).update_first_affected_discs
            launch(q, k, p.photons, *args, discs.nodes, discs.blocks, np.int32(discs.count_emitted),
                   np.float32(discs.radius ** 2), np.float32(discs.ext), np.float32(self.scale), discs.acc,
                   discs.work_buf, local_size=engine.local_size)
        cl.enqueue_copy(q, self.first_host, self.first)
        paths = np.nonzero(self.first_host >= 0)[0].astype(np.int32)
        return paths, self.first_host[paths]

    def _refresh_view(self) -> int:
        """Re-trace the pixels that may see a movable object. Impact Count:
        the changed pixels are re-pointed (its sums are per triangle). DETP:
        a fresh estimator over the dynamic points, its sums still empty
        (``move`` fills them)."""
        changed, dynamic = self.view.update()
        if not self.estimator.sums_per_point:
            if len(changed):
                self.estimator.replace_points(changed, self.view.subset(changed))
            return len(changed)
        self._new_dynamic()
        return len(dynamic)

    def _new_dynamic(self):
        """An estimator of the ``dynamic`` variant over the view's dynamic points."""
        self.dyn_index = self.view.dynamic
        self.dyn_est = None
        if len(self.dyn_index) == 0:
            return
        p = self.params
        options = self.options if self.dynamic == p.method else {"count_work": self.options["count_work"]}
        from dataclasses import replace

        self.dyn_est = self.engine.estimator(self.view.subset(self.dyn_index), replace(p, method=self.dynamic),
                                             **options)

    def _accumulate_suffixes(self, paths_buf, starts_buf, n_list: int, sign: float, estimators):
        p = self.params
        nbytes = n_list * p.max_depth * Segment.itemsize
        if self.scratch is None or self.scratch.size < nbytes:
            # grow geometrically, never past the store itself
            size = max(nbytes, min(2 * (self.scratch.size if self.scratch else 0), self.store_bytes))
            self.scratch = cl.Buffer(self.engine.ctx, cl.mem_flags.READ_WRITE, size)
        launch(self.queue, self.k_gather, n_list, self.store.segments, np.int32(p.max_depth), paths_buf,
               starts_buf, np.int32(n_list), np.float32(sign), self.scratch)
        # Path ids stay in the gathered slots; the scratch store is a batch
        # of n_list paths like any other.
        batch = PathBatch(self.scratch, self.store.path_len, 0, n_list, p.max_depth)
        for est in estimators:
            est.accumulate(batch, self.scale)
