"""Photon Maps kept up to date as objects move (DESIGN.md section 4).

A k-nearest estimate is not a sum of per-segment terms (an impact that
arrives or leaves changes which impacts are a point's k nearest, and r_k),
so the exact add-and-subtract update of ``Session`` does not apply. The
thesis' answer (García 2004, 2007): Photon Maps made exactly equal to a
recomputation are slower than recomputing, so the *practical* update
"estimates with the new impacts and recomputes the moving object fully
(not equal to recomputation, tends to it)". Here:

- The session keeps every path in a ``SegmentStore``; a move re-traces the
  affected suffixes, so the store, and the map of impacts gathered from it,
  equal a fresh trace at the new pose bit for bit.
- ``mode="practical"``: the impacts that changed (those of the old
  suffixes, read before the re-trace, and of the new ones) update the sums
  of the points whose ball (centre x, radius r_k of the point's last
  k-nearest search) holds them: removed impacts subtract their power,
  added ones add it, the radius stays (kernels/photon_map_update.cl).
  Points on the moving object moved with it: their k nearest are searched
  again in the new map. Fixed-point sums make this path-independent: a
  static point's estimate is exactly the fixed-radius estimate, with the
  radius of the first frame, over the current impacts (up to ties at r_k).
  It differs from recomputation where the impacts near a point changed
  (the k-th nearest moved: shadows and light the object moved), by about
  the estimator's own noise, and it tends to recomputation as r_k shrinks
  with more photons. Errors do not pile up over frames: back at the first
  pose every estimate is the first frame's again, bit for bit.
- ``mode="exact"``: the points whose closed ball holds a changed impact
  are listed (the others keep their k nearest: nothing of theirs left,
  nothing that arrived ranks before their k-th) and searched again with
  the points on the moving object: every estimate equals a recomputation
  from scratch bit for bit (ranks are (d2, canonical id); an impact's
  canonical id shifts when earlier paths gain or lose impacts, but the
  relative order of the impacts that stay does not).

Costs per move: the store's find pass and the re-trace (as ``Session``);
the changed impacts walk a BVH over the balls (O(changed log n_P)); when
some point must be searched again (points on the moving object, or exact
mode), the impacts are gathered from the store and their index rebuilt
(O(N log N), as a fresh PhotonMap does: it is what most of such a move
costs), the listed points searched, and the ball BVH rebuilt over the
points (host numpy, O(n_P log n_P), small beside the impacts' index).
Host bookkeeping of which points to search is O(listed).

Points on a movable object: a query point whose triangle (``tri``, as
``engine.vertex_points()`` and camera points carry) belongs to a movable
object is attached to it and follows its moves (positions by the object's
matrix, normals by its inverse transpose).

    >>> import numpy as np, oclgi
    >>> scene = oclgi.load_file(oclgi.scene_path("cornell_box.toml"))
    >>> pts = np.array([[0, 0.01, 0, 0, 1, 0]])
    >>> session = oclgi.PhotonMapSession(oclgi.Engine(scene), pts, photons=5000, k=20)
    >>> session.irradiance().shape
    (1, 3)
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from ..accel.bvh_build import build_bvh
from ..cl.programs import launch, programs, read_buffer
from ..engine import as_query_points
from ..errors import OclgiError
from ..accel.boxes import PAD, active_discs, check_depth, coordinate_scale, outward_f32
from ..estimators.photon_map import DEFAULT_K
from ..queries import QueryPoints
from ..scene.pose import as_transform
from .protocol import SessionBase, UpdateStats
from .segment_store import SegmentStore

MODES = ("practical", "exact")
BALL_LEAF = 8  # balls per leaf of the ball BVH
UNBOUNDED = 1e30  # half-extent of the box of a ball with r_k = inf (fewer than k impacts)


class BallIndex:
    """A BVH over the query points' balls (x_i, r_k,i), on the device.

    Boxes are padded like DETP's disc boxes (``PAD`` times the coordinate
    scale, far above float32 rounding) and rounded outward, so every impact
    the kernel's exact test accepts reaches its ball's leaf. ``unbounded``:
    whether balls with r_k = inf are indexed (exact mode: any change may
    give such a point k impacts; practical mode: their E stays 0).
    """

    def __init__(self, queue, compiled, points: QueryPoints, r2: np.ndarray, unbounded: bool):
        ids = active_discs(points)
        if not unbounded:
            ids = ids[np.isfinite(r2[ids])]
        self.n = len(ids)
        self.nodes = self.balls = None
        if not self.n:
            return
        pos = points.positions[ids, :3].astype(np.float64)
        r = np.sqrt(r2[ids].astype(np.float64))
        half = np.where(np.isfinite(r), r + PAD * coordinate_scale(compiled, pos), UNBOUNDED)[:, None]
        lo, hi = outward_f32(pos - half, pos + half)
        bvh = build_bvh(lo, hi, BALL_LEAF)
        check_depth(bvh.depth, "balls")
        mf = cl.mem_flags
        ctx = queue.context
        self.nodes = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=bvh.nodes)
        self.balls = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=ids[bvh.order].astype(np.int32))


class PhotonMapSession(SessionBase):
    """Photon Map irradiance at query points, kept up to date under moves.

    ``points``: QueryPoints or an (n, 6) array (x y z nx ny nz), or None
    for the visible points of ``camera`` (the scene's by default; after a
    move the pixels that may see a movable object are traced again,
    oclgi/incremental/dynamic_view.py, and searched again); ``photons``,
    ``seed``, ``max_depth``, ``count_emitted`` as for
    :meth:`oclgi.Engine.irradiance` (the scene's by default); ``k``,
    ``estimator``, ``front_only``, ``leaf_size`` as for the
    ``photon_map`` estimator; ``mode``: "practical" (the thesis' update,
    module docstring) or "exact" (equal to recomputation). The session has
    a pose of its own, as ``oclgi.Session`` has (``self.engine``).
    """

    def __init__(self, engine, points=None, photons=None, seed=None, max_depth=None, k=DEFAULT_K,
                 estimator="k-1", count_emitted=None, mode="practical", front_only=True, leaf_size=16,
                 camera=None):
        if mode not in MODES:
            raise OclgiError(f"Photon Map session mode must be one of {', '.join(map(repr, MODES))}, got {mode!r}")
        self.engine = engine.posed(owner=self)
        self.queue, self.mode = engine.queue, mode
        self.params = self.engine.run_params("photon_map", photons, None, seed, max_depth, None, count_emitted)
        self.options = dict(k=k, estimator=estimator, front_only=front_only, leaf_size=leaf_size)
        self.view = None
        if points is None:
            self._new_view(camera)
        else:
            self.points = as_query_points(points).copy()
        self.map = self.engine.estimator(self.points, self.params, **self.options)  # validates the options
        t0 = time.perf_counter()
        p = self.params
        self.store = SegmentStore(self.engine, p.photons, p.seed, p.max_depth)
        self.scale = self.store.scale
        prog = programs(engine.ctx).get("photon_map_update")
        self.k_update, self.k_unmark = prog.pm_update_balls, prog.pm_unmark
        self._search_all()
        self.setup_seconds = time.perf_counter() - t0

    # -- setup --------------------------------------------------------------
    def _new_view(self, camera) -> None:
        """The visible points of ``camera`` as the query points."""
        from .dynamic_view import DynamicView

        self.view = DynamicView(self.engine, camera)
        self.points = self.view.points.copy()

    def _new_map(self, options: dict) -> None:
        """A map with ``options`` (validated) over the current points, every point searched in the store."""
        self.map = self.engine.estimator(self.points.copy(), self.params, **options)
        self.options, self.points = options, self.map.points
        self._search_all()

    def _search_all(self):
        """Every point searched in the store's impacts (a fresh session's
        state at the session's pose), the balls and their marks anew."""
        self._gather()
        self.map.search()
        self.attached = self._attach()
        self.balls = self._balls()
        n = max(len(self.points), 1)
        self.marks = self.map.zeros(n * 4)
        self.listed = cl.Buffer(self.engine.ctx, cl.mem_flags.READ_WRITE, n * 4)
        self.n_listed = self.map.zeros(4)
        self.queue.finish()

    def set_estimator(self, method: str | None = None, **options) -> float:
        """Other Photon Map options from now on (``k``, ``estimator``,
        ``front_only``, ``leaf_size``; the others keep theirs):
        the stored paths' impacts are searched again, nothing is re-traced;
        equal to a fresh session with these options at the session's pose.
        ``method`` must be "photon_map" (a DETP or Impact Count session is
        an ``oclgi.Session``). Returns the seconds it took."""
        self._check_open()
        if method not in (None, "photon_map"):
            raise OclgiError(f"a Photon Map session estimates with photon_map; for {method!r} open an "
                             "oclgi.Session (oclgi.open_session picks the kind)")
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            raise OclgiError(f"unknown Photon Map session option(s) {', '.join(unknown)}; "
                             f"known: {', '.join(self.options)}")
        t0 = time.perf_counter()
        self._new_map(dict(self.options, **options))
        return time.perf_counter() - t0

    def set_photons(self, photons: int) -> float:
        """Keep ``photons`` paths from now on (more traced, only the new
        ones; fewer dropped) and search every point again in their impacts:
        equal to a fresh session with that count at the session's pose.
        Returns the seconds it took."""
        self._check_open()
        t0 = time.perf_counter()
        p = self.params
        new_params = self.engine.run_params("photon_map", photons, None, p.seed, p.max_depth, None, p.count_emitted)
        store, _ = self.store.resized(new_params.photons)
        old, self.store, self.params, self.scale = self.store, store, new_params, store.scale
        self._release_store(old)
        self._new_map(self.options)
        return time.perf_counter() - t0

    def _apply_parameters(self, changes: dict):
        """An update (oclgi/scene_parameters.py): materials and lights, seed and
        depth re-trace the store; photons trace or drop the difference; a
        camera traces its points; then every point is searched again (a
        k-nearest estimate depends on every impact)."""
        from ..scene_parameters import Updated, kinds

        t0 = time.perf_counter()
        what = kinds(changes)
        for key in ("method", "radius", "extension"):
            if key in changes and not (key == "method" and changes[key] == "photon_map"):
                raise OclgiError(f"a Photon Map session has no {key} to change (its k and options: set_estimator; "
                                 "another method: an oclgi.Session)")
        scene, compiled, run = self._new_tables(changes)
        p = self.params
        new = self.engine.run_params("photon_map", run.get("photons", p.photons), None, run.get("seed", p.seed),
                                     run.get("max_depth", p.max_depth), None,
                                     run.get("count_emitted", p.count_emitted))
        done = Updated(tables=compiled is not None)
        self._renew_store(scene, compiled, what, new, done)
        if self.view is not None and ("camera" in what or (compiled is not None and self.view.through)):
            self._new_view(changes.get("camera", self.view.cam))
            done.points_traced = len(self.points)
        self._new_map(self.options)
        done.resummed = True
        done.seconds = time.perf_counter() - t0
        return done

    def set_camera(self, camera) -> float:
        """View through ``camera`` from now on (camera sessions only): its
        points traced at the session's pose and searched in the stored
        impacts; no photon is re-traced. Returns the seconds it took."""
        self._check_camera(self.view is not None, "set_camera")
        t0 = time.perf_counter()
        self._new_view(camera)
        self._new_map(self.options)
        return time.perf_counter() - t0

    def _gather(self):
        """The map: every impact of the store, in canonical order (its index is built when searched)."""
        self.map.clear_impacts()
        self.map.accumulate(self.store.batch)
        self.map_current = True

    def _attach(self) -> dict:
        """Per movable object: its points (their triangle is the object's), their
        positions and normals as given, and the object's pose then."""
        scene, compiled = self.engine.scene, self.engine.compiled
        tri = self.points.tri
        out = {}
        if self.view is not None:
            return out  # a camera's points are traced again instead (DynamicView)
        for obj, (a, b) in enumerate(scene.object_ranges()):
            ids = np.nonzero((tri >= a) & (tri < b))[0]
            if scene.objects[obj].movable and len(ids):
                pose = as_transform(compiled.instances_host[obj]["world_from_object"].astype(np.float64))
                out[obj] = (ids, self.points.positions[ids].copy(), self.points.normals[ids].copy(), pose)
        return out

    def _balls(self) -> BallIndex:
        r2 = read_buffer(self.queue, self.map.r2, len(self.points), np.float32)
        return BallIndex(self.queue, self.engine.compiled, self.points, r2, unbounded=self.mode == "exact")

    def _place_points(self, obj: int, matrix) -> np.ndarray:
        """Move the points attached to ``obj`` to the object's new pose; their ids."""
        if obj not in self.attached:
            return np.zeros(0, np.int64)
        ids, pos0, nrm0, pose0 = self.attached[obj]
        m = as_transform(matrix)
        moved = QueryPoints(pos0.copy(), nrm0.copy(), self.points.barys[ids].copy())
        if not np.array_equal(m, pose0):  # back at the first pose: the points as given, bit for bit
            rel = m @ np.linalg.inv(pose0)
            moved.positions[:, :3] = pos0[:, :3].astype(np.float64) @ rel[:3, :3].T + rel[:3, 3]
            n = nrm0[:, :3].astype(np.float64) @ np.linalg.inv(rel[:3, :3])  # inverse transpose
            moved.normals[:, :3] = n / np.linalg.norm(n, axis=1)[:, None]
        self.map.replace_points(ids, moved)
        return ids

    # -- reading ------------------------------------------------------------
    def irradiance(self) -> np.ndarray:
        """(n, 3) irradiance at the query points (their current positions), W/m^2."""
        self._check_open()
        return read_buffer(self.queue, self.map.irradiance_buffer(self.scale), (len(self.points), 4), np.float32)[:, :3]

    def accumulators(self) -> np.ndarray:
        """The exact fixed-point sums behind the irradiance, (n, 3) int64."""
        self._check_open()
        return self.map.accumulators()

    def render(self, exposure: float = 1.0):
        """(radiance (H, W, 3), tone-mapped pixels (H, W, 4)) of the camera view."""
        self._check_camera(self.view is not None, "render")
        buf = self.map.irradiance_buffer(self.scale)
        return self.engine.shade(self.view.points, buf, exposure)  # the composite: positions and path weights

    def radii(self) -> np.ndarray:
        """r_k of each point: of its last k-nearest search (practical mode keeps it for static points)."""
        return self.map.radii()

    def impacts(self):
        """The map's impacts at the current pose, canonical order: positions, directions, powers."""
        if not self.map_current:
            self._gather()
        return self.map.impacts()

    def segments(self) -> tuple[np.ndarray, np.ndarray]:
        return self.store.segments(), self.store.path_len()

    def recompute(self, seed=None):
        """A Photon Map estimate from scratch at the current pose and points
        (an ``Estimate``; ``seed`` another seed, to measure the noise)."""
        p = self.params
        self._check_open()
        return self.engine.irradiance(self.points.copy(), method="photon_map", photons=p.photons,
                                      seed=p.seed if seed is None else seed, max_depth=p.max_depth,
                                      count_emitted=p.count_emitted, **self.options)

    # -- moving -------------------------------------------------------------
    def move(self, name: str, matrix) -> UpdateStats:
        """Place movable object ``name`` (4x4 world-from-object matrix) and update."""
        obj, t0 = self._place(name, matrix)
        q = self.queue
        moved = self._place_points(obj, matrix)
        if self.view is not None:
            moved, _ = self.view.update()  # the pixels that may see a movable object, traced again
            if len(moved):
                self.map.replace_points(moved, self.view.subset(moved))
        affected = self.store.find(obj)
        t1 = time.perf_counter()
        seconds = {"find": t1 - t0}
        stats = UpdateStats(paths=len(affected), segments_removed=0, segments_added=0)
        exact = self.mode == "exact"
        if len(affected):
            cl.enqueue_fill_buffer(q, self.n_listed, np.int32(0), 0, 4)
            removed = self.store.suffix_count(affected)
            self._update_balls(affected, -1.0, exact)
            q.finish()
            t2 = time.perf_counter()
            self.store.retrace(affected)
            q.finish()
            t3 = time.perf_counter()
            added = self.store.suffix_count(affected)
            self._update_balls(affected, 1.0, exact)
            q.finish()
            stats.segments_removed, stats.segments_added = int(removed), int(added)
            t4 = time.perf_counter()
            seconds.update(retrace=t3 - t2, balls=(t2 - t1) + (t4 - t3))
            self.map_current = False
        search = moved
        if exact and len(affected):
            search = np.union1d(moved, self._listed())
        stats.points = len(search)
        if len(search):
            t5 = time.perf_counter()
            if not self.map_current:
                self._gather()
            self.map.search(search)  # builds the index first
            q.finish()
            t6 = time.perf_counter()
            self.balls = self._balls()  # the searched points' balls changed
            seconds.update(search=t6 - t5, ball_index=time.perf_counter() - t6)
        seconds["total"] = time.perf_counter() - t0
        stats.seconds = seconds
        return stats

    def _update_balls(self, affected, sign: float, mark: bool):
        """The impacts of the affected suffixes, as the store holds them now,
        through the balls (kernels/photon_map_update.cl)."""
        b, m, s = self.balls, self.map, self.store
        if b.nodes is None:
            return
        launch(self.queue, self.k_update, len(affected), b.nodes, b.balls, m.positions, m.normals, m.r2,
               s.batch.segments, s.max_depth, affected.paths_buf, affected.starts_buf,
               len(affected), m.count_emitted, m.front_only, mark,
               m.estimator == "k", sign, m.acc, self.marks,
               self.listed, self.n_listed, local_size=self.engine.local_size)

    def _listed(self) -> np.ndarray:
        """The points the exact mode listed (O(listed) to read); their marks cleared."""
        ids = np.empty(int(read_buffer(self.queue, self.n_listed, 1, np.int32)[0]), np.int32)
        if len(ids):
            cl.enqueue_copy(self.queue, ids, self.listed)
            launch(self.queue, self.k_unmark, len(ids), self.listed, len(ids), self.marks)
        return ids
