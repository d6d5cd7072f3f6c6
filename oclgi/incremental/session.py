"""Interactive sessions: illumination kept up to date as objects move.

A session traces every photon path once and keeps all segments on the
device (path-major, DESIGN.md section 2; oclgi/incremental/segment_store.py). After
``move(name, matrix)`` only the paths the move touches change (DESIGN.md
section 4, García 2004/2007): their old suffixes are gathered with negated
power and accumulated (their contributions leave the sums exactly), the
suffixes are re-traced in place, and the new suffixes are accumulated.

Sums are fixed point, so the result equals a recomputation from scratch at
the new pose bit for bit, however many moves came before: errors never
accumulate. Query points are either fixed (sensors: an array of points and
normals) or the visible points of a camera (``points=None``, see
oclgi/incremental/dynamic_view.py): pixels on static surfaces are updated like fixed
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
from dataclasses import replace

import numpy as np
import pyopencl as cl

from ..cl.programs import read_buffer
from ..engine import as_query_points
from ..errors import OclgiError
from ..estimators.detp_disc_index import DetpDiscIndex
from .protocol import SessionBase, UpdateStats  # noqa: F401 (UpdateStats: the sessions' result)
from .segment_store import SegmentStore


# the options of the light a DETP estimate takes (detp_direct.py, final_gather.py), whichever variant
LIGHT_OPTIONS = ("direct", "direct_samples", "direct_mis", "gather", "gather_seed")


def _add_work(total: dict | None, more: dict | None) -> dict | None:
    if total is None or more is None:
        return total or more
    return {k: total[k] + more[k] for k in total}


class Session(SessionBase):
    """A scene, an estimator and query points, kept up to date under moves.

    ``points``: QueryPoints or an (n, 6) array (x y z nx ny nz); the other
    arguments as for :meth:`oclgi.Engine.irradiance`; ``dynamic``: the DETP
    variant that recomputes a camera session's dynamic points (default
    ``detp_disc_index``). Every segment of every path stays on the device:
    memory is photons x max_depth x 48 bytes.

    The session has a pose of its own (``self.engine`` is its view of the
    engine, oclgi/scene/pose.py), starting from the engine's current pose:
    several sessions over one engine move independently, and moving the
    engine does not move them. ``session.engine.irradiance(...)`` recomputes
    at the session's pose.

    ``paths``: a PathRange of the run's path ids to store and update instead
    of all of them (a rank's part, oclgi/distributed.py): the sums are then
    that range's, in the scale of the whole run's ``photons``.
    """

    # How a camera session's disc-indexed dynamic points are summed over the
    # moved store: "listed" (default), after the update, over only the paths
    # whose cell masks meet the discs' box (SegmentStore.sum_near); "find",
    # over the old store in the find pass, then brought to the new one by
    # the suffix passes with the static points; "store", over every stored
    # path after the update. All three give the same sums bit for bit; the
    # other two are kept to measure against. Other DETP variants: "store".
    dynamic_pass = "listed"
    # True: disc-indexed estimators sum a move's old and new suffixes in one
    # pass after the re-trace, skipping what the first segments share
    # (DetpDiscIndex.accumulate_change); False: a subtraction pass, then an
    # addition pass (the plain form, kept to test the other against).
    sum_changes = True

    def __init__(self, engine, points=None, method=None, photons=None, radius=None, seed=None, max_depth=None,
                 extension=None, count_emitted=None, count_work=False, camera=None, dynamic=None, paths=None,
                 **options):
        self.engine = engine.posed(owner=self)
        self.queue = engine.queue
        self.params = self.engine.run_params(method, photons, radius, seed, max_depth, extension, count_emitted)
        self._check_method(self.params.method, dynamic, options, points is None)
        self.camera = camera
        self.options = dict(options, count_work=count_work)
        self.dynamic_choice = dynamic
        self.view = None
        self.fixed_points = None if points is None else as_query_points(points).copy()
        self._new_view(camera)
        t0 = time.perf_counter()
        p = self.params
        if paths is None:
            self.store = SegmentStore(self.engine, p.photons, p.seed, p.max_depth)
        else:
            if not (0 <= paths.first and 0 < paths.count and paths.end <= p.photons):
                raise OclgiError(f"paths {paths.first}..{paths.end} are not a non-empty part of the session's "
                                 f"{p.photons:,} photons")
            self.store = SegmentStore(self.engine, paths.count, p.seed, p.max_depth, first=paths.first,
                                      total=p.photons)
        self.scale = self.store.scale
        self._accumulate_all()
        self.setup_seconds = time.perf_counter() - t0

    @property
    def is_camera(self) -> bool:
        """Whether the query points are a camera's view."""
        return self.view is not None and self.view.cam is not None

    # -- setting up -----------------------------------------------------------
    @staticmethod
    def _check_method(method: str, dynamic, options: dict, camera: bool) -> None:
        from ..estimators import ESTIMATORS
        cls = ESTIMATORS[method]
        if not cls.incremental:
            raise OclgiError(f"method {method!r} has no exact incremental update; sessions take "
                             f"{', '.join(m for m, c in ESTIMATORS.items() if c.incremental)}")
        if camera and options.get("radius_mode", "fixed") != "fixed":
            # Adaptive radii are fixed when the estimator is built (the first
            # frame); a camera session's dynamic points are new every frame.
            raise OclgiError("radius_mode 'adaptive' needs a session over given points (points=...), "
                             "not a camera session")
        detp_variants = [m for m, c in ESTIMATORS.items() if c.family == "detp"]
        chosen = dynamic or ("detp_disc_index" if cls.family == "detp" else method)
        if chosen not in detp_variants and (cls.sums_per_point or dynamic is not None):
            raise OclgiError(f"dynamic points are recomputed by a DETP variant ({', '.join(detp_variants)}), "
                             f"got {chosen!r}")

    def _new_view(self, camera) -> None:
        """The query points: the given ones (with those on movable objects
        attached to them), or the camera's two layers."""
        if self.fixed_points is not None:
            from .attached_points import AttachedPoints

            attached = AttachedPoints(self.engine, self.fixed_points)
            self.view = attached if len(attached.dynamic) else None
            self.points = attached.points if self.view is not None else self.fixed_points
            return
        from .dynamic_view import DynamicView

        self.view = DynamicView(self.engine, camera)
        self.camera = self.view.cam
        self.points = self.view.points  # the composite view, kept current by the view

    def _accumulate_all(self) -> None:
        """The estimators over the current points, summed over the whole
        store (a fresh session's state at the session's pose, without a
        trace)."""
        from ..estimators import ESTIMATORS

        p = self.params
        cls = ESTIMATORS[p.method]
        if self.view is None:
            est_points = self.points
        else:
            # DETP keeps sums per point: the estimator holds the static layer
            # for good; Impact Count keeps sums per triangle and just shades
            # whichever point each pixel sees.
            est_points = self.view.static if cls.sums_per_point else self.view.points.copy()
        self.dynamic = self.dynamic_choice or ("detp_disc_index" if cls.family == "detp" else p.method)
        # the static points' index is walked on every move: built for that
        # (DetpDiscIndex.session_tree), unless the options say otherwise
        self.estimator = self.engine.estimator(est_points, p, request_points=len(self.points),
                                               **{**getattr(cls, "session_tree", {}), **self.options})
        if isinstance(self.estimator, DetpDiscIndex):
            self.estimator.list_crossings = True  # it lives as long as the store (DetpDiscIndex.accumulate_change)
        self.estimator.accumulate(self.store.batch)
        self.dyn_est, self.dyn_index, self.dynamic_work = None, np.zeros(0, np.int64), None
        if self.view is not None and cls.sums_per_point:
            self._new_dynamic()
            if self.dyn_est is not None:
                self.dyn_est.accumulate(self.store.batch)
                self.dynamic_work = self.dyn_est.work()
        self.queue.finish()

    # -- changing what is estimated (no re-trace) ------------------------------------
    def set_estimator(self, method: str | None = None, radius: float | None = None,
                      extension: float | None = None, count_emitted: bool | None = None, dynamic=None,
                      **options) -> float:
        """Estimate with another incremental method or other options from
        now on: the stored paths are summed again, nothing is re-traced.
        None keeps the session's current value; ``options`` replace the
        method's options (``count_work`` stays). Equal bit for bit to a
        fresh session with these settings at the session's pose. Returns
        the seconds it took."""
        self._check_open()
        t0 = time.perf_counter()
        p = self.params
        new = self.engine.run_params(method or p.method, p.photons, p.radius if radius is None else radius,
                                     p.seed, p.max_depth, p.extension if extension is None else extension,
                                     p.count_emitted if count_emitted is None else count_emitted)
        self._check_method(new.method, dynamic, options, self.is_camera)
        self.params = new
        self.options = dict(options, count_work=self.options["count_work"])
        self.dynamic_choice = dynamic
        self._accumulate_all()
        return time.perf_counter() - t0

    def set_photons(self, photons: int) -> float:
        """Keep ``photons`` paths from now on: more are traced (only the new
        ones) and added to the sums, fewer are taken out of them; equal bit
        for bit to a fresh session with that count at the session's pose.
        Returns the seconds it took."""
        self._check_open()
        t0 = time.perf_counter()
        p = self.params
        new_params = self.engine.run_params(p.method, photons, p.radius, p.seed, p.max_depth, p.extension,
                                            p.count_emitted)
        store, delta = self.store.resized(new_params.photons)
        if delta is not None:
            for est in (self.estimator, self.dyn_est):
                if est is not None:
                    est.accumulate(delta)
        self.queue.finish()
        old, self.store, self.params, self.scale = self.store, store, new_params, store.scale
        self._release_store(old)
        return time.perf_counter() - t0

    def _apply_parameters(self, changes: dict):
        """An update (oclgi/scene_parameters.py): materials and lights, seed and
        depth re-trace the store; photons trace or drop only the difference;
        a camera traces its points; the estimator's parameters re-sum."""
        from ..scene_parameters import Updated, kinds

        t0 = time.perf_counter()
        what = kinds(changes)
        scene, compiled, run = self._new_tables(changes)  # checked: nothing changed yet
        p = self.params
        new = self.engine.run_params(*(run.get(k, getattr(p, k)) for k in (
            "method", "photons", "radius", "seed", "max_depth", "extension", "count_emitted")))
        self._check_method(new.method, self.dynamic_choice, self.options, self.is_camera)
        if (self.store.first_path != 0 or self.store.total != self.store.photons) and what - {"camera", "estimate"}:
            raise OclgiError("a session over part of a run's paths (a rank's) changes only its camera and estimator")
        done = Updated(tables=compiled is not None)
        if what == {"photons"}:  # the difference only, into the sums as they are
            done.paths_traced = max(new.photons - p.photons, 0)
            done.paths_dropped = max(p.photons - new.photons, 0)
            self.set_photons(new.photons)
            done.seconds = time.perf_counter() - t0
            return done
        self._renew_store(scene, compiled, what, new, done)
        if self.view is not None and ("camera" in what or (compiled is not None and self.view.through)):
            self._new_view(changes.get("camera", self.view.cam))
            done.points_traced = len(self.points)
        self._accumulate_all()
        done.resummed = True
        done.seconds = time.perf_counter() - t0
        return done

    def set_camera(self, camera) -> float:
        """View through ``camera`` (an oclgi.Camera) from now on: the camera
        points are traced again at the session's pose and summed over the
        stored paths; no photon is re-traced. Camera sessions only. Returns
        the seconds it took."""
        self._check_camera(self.is_camera, "set_camera")
        t0 = time.perf_counter()
        self._new_view(camera)
        self._accumulate_all()
        return time.perf_counter() - t0

    # -- reading ------------------------------------------------------------
    def _irradiance4(self) -> np.ndarray:
        out = read_buffer(self.queue, self.estimator.resolve(self.scale), (len(self.points), 4), np.float32)
        if self.dyn_est is not None:
            out[self.dyn_index] = read_buffer(self.queue, self.dyn_est.resolve(self.scale), (len(self.dyn_index), 4),
                                              np.float32)
        return out

    def irradiance(self) -> np.ndarray:
        """(n, 3) irradiance at the query points (the pixels' current visible points), W/m^2."""
        self._check_open()
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
        return self.store.segments(), self.store.path_len()

    def render(self, exposure: float = 1.0):
        """(radiance (H, W, 3), tone-mapped pixels (H, W, 4)) of the camera view."""
        self._check_open()  # (before its points are read)
        self._check_camera(self.points.kind == "camera", "render")
        irr = self._irradiance4()
        buf = cl.Buffer(self.engine.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=irr)
        return self.engine.shade(self.points, buf, exposure)

    # -- moving -----------------------------------------------------------------
    def move(self, name: str, matrix) -> UpdateStats:
        """Place object ``name`` (4x4 world-from-object matrix) and update."""
        obj, t0 = self._place(name, matrix)
        q, seconds = self.queue, {}
        # A disc-indexed dynamic estimator takes its sums over the old store
        # in the find pass ("find", dynamic_pass); the suffix passes below
        # then update them as they update the static points (update.cl).
        # Otherwise they are summed over the new store at the end; "listed"
        # builds their index on the host while the device re-traces, and
        # its paths are listed by the find, in a box known before the index.
        mode = self._dynamic_mode()
        deferred = mode == "listed"
        n_view = self._refresh_view(build=not deferred) if self.view is not None else 0
        near = self._near_box() if deferred and len(self.dyn_index) else None
        t1 = time.perf_counter()
        if self.view is not None:
            seconds["points"] = t1 - t0
        fused = self.dyn_est is not None and mode == "find"
        affected = self.store.find(obj, self.dyn_est if fused else None, near=near)
        t2 = time.perf_counter()
        seconds["find"] = t2 - t1
        stats = UpdateStats(paths=len(affected), segments_removed=0, segments_added=0, points=n_view)
        estimators = [self.estimator] + ([self.dyn_est] if fused else [])
        if len(affected):
            removed = self.store.suffix_count(affected)
            # One pass after the re-trace (then "subtract" is the gather alone)
            # or a pass on each side of it.
            change = self.sum_changes and all(est.sums_changes for est in estimators)
            old = self.store.suffixes(affected, -1.0)
            if not change:
                for est in estimators:
                    est.accumulate(old)
            q.finish()  # honest per-stage times
            t3 = time.perf_counter()
            self.store.retrace(affected)
            added = self.store.suffix_count(affected)
            if deferred:  # host work while the device re-traces: in the re-trace's time
                self._new_dynamic()
                deferred = False
            q.finish()
            t4 = time.perf_counter()
            if change:
                for est in estimators:
                    est.accumulate_change(old, self.store.batch, affected)
            else:
                new = self.store.suffixes(affected, 1.0)
                for est in estimators:
                    est.accumulate(new)
            q.finish()
            stats.segments_removed, stats.segments_added = int(removed), int(added)
            t5 = time.perf_counter()
            seconds.update(subtract=t3 - t2, retrace=t4 - t3, add=t5 - t4)
        if hasattr(self.estimator, "regather"):  # final gathering: the rays the move changed, their new discs
            t6 = time.perf_counter()
            stats.rays_changed = self.estimator.regather(self.store.batch)
            q.finish()
            seconds["gather"] = time.perf_counter() - t6
        if deferred:  # nothing was re-traced
            t6 = time.perf_counter()
            self._new_dynamic()
            seconds["points"] += time.perf_counter() - t6
        if self.dyn_est is not None and not fused:
            t6 = time.perf_counter()
            if mode == "listed":
                self.store.sum_near(self.dyn_est)
            else:
                self.dyn_est.accumulate(self.store.batch)
            q.finish()
            seconds["points"] += time.perf_counter() - t6
        if self.dyn_est is not None:
            self.dynamic_work = _add_work(self.dynamic_work, self.dyn_est.work())
        seconds["total"] = time.perf_counter() - t0
        stats.seconds = seconds
        return stats

    def _dynamic_mode(self) -> str | None:
        """How a move sums the dynamic points (``dynamic_pass``; "store"
        for a variant that cannot sum in the find pass); None: the session
        keeps no sums per dynamic point."""
        from ..estimators import ESTIMATORS

        if self.view is None or not self.estimator.sums_per_point:
            return None
        if self.options.get("gather", 0):
            return "store"  # a gathered point's discs sit at its rays' hits, not at the point
        return self.dynamic_pass if ESTIMATORS[self.dynamic].fuses_with_find else "store"

    def _refresh_view(self, build: bool = True) -> int:
        """Re-trace the pixels that may see a movable object. Impact Count:
        the changed pixels are re-pointed (its sums are per triangle). DETP:
        the dynamic points, and (``build``) a fresh estimator over them, its
        sums still empty (``move`` fills them); else ``_new_dynamic`` later."""
        changed, dynamic = self.view.update()
        if not self.estimator.sums_per_point:
            if len(changed):
                self.estimator.replace_points(changed, self.view.subset(changed))
            return len(changed)
        self.dyn_index, self.dyn_est = self.view.dynamic, None
        if build:
            self._new_dynamic()
        return len(dynamic)

    def _near_box(self) -> tuple[np.ndarray, np.ndarray]:
        """A box around the dynamic points holding every disc box their
        index will have (``disc_boxes``: at most the radius and the pad from
        each centre): what the find lists paths in for them before the index
        exists. SegmentStore.sum_near checks that it holds the index's box."""
        from ..accel.boxes import PAD, column_bounds, coordinate_scale

        lo, hi = (b.astype(np.float64) for b in column_bounds(self.view.points.positions[self.dyn_index, :3]))
        margin = 1.001 * self.params.radius + 2.0 * PAD * coordinate_scale(self.engine.compiled, np.stack([lo, hi]))
        return lo - margin, hi + margin

    def _new_dynamic(self):
        """An estimator of the ``dynamic`` variant over the view's dynamic points."""
        self.dyn_index = self.view.dynamic
        self.dyn_est = None
        if len(self.dyn_index) == 0:
            return
        from ..estimators import ESTIMATORS

        p = self.params
        # another variant takes the method's light options only: the direct light's and the gather's
        options = self.options if self.dynamic == p.method else {
            k: v for k, v in self.options.items() if k == "count_work" or k in LIGHT_OPTIONS}
        # an index built on every move, walked once (DetpDiscIndex.dynamic_tree)
        options = {**getattr(ESTIMATORS[self.dynamic], "dynamic_tree", {}), **options}
        self.dyn_est = self.engine.estimator(self.view.subset(self.dyn_index), replace(p, method=self.dynamic),
                                             request_points=len(self.points), **options)
