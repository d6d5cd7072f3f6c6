"""Moving lights by path reuse (driver of ``kernels/light_reuse.cl``).

Sbert, Szecsi and Szirmay-Kalos, "Real-time light animation" (CGF 2004):
trace the paths of all F light positions of an animation once, keep each
path from its first hit on, and for every frame connect the frame's light
position to every stored first hit, weighting by multiple importance
sampling (balance heuristic) over the F positions. This first increment
takes one point or spot light, the scene's only emitter, on diffuse
surfaces (the tail after a diffuse first hit does not depend on where the
light was, only on which side of the surface it arrived from).

Derivation (one frame j, light at y_j; everything per channel)
----------------------------------------------------------------
What any estimator sums is a functional of the photon paths. Split a path
at its first hit x: the light emits towards x with intensity I_j(x) (W/sr;
for a spot, the axis intensity times pbrt-v4's profile), which arrives as
the flux density (per m^2 at x) f_j(x) = I_j(x) cos_x / r_j(x)^2 V_j(x);
the rest of the path is the tail, whose distribution given x (and the side
it is lit from) is the same for every light position on diffuse surfaces.
A photon of an ordinary run of N paths from y_j reaches x with area
density p_j(x) = pdf_j(w) cos_x / r^2 V (light_pdf_dir converted from
solid angle to area at x: d_omega = cos_x dA / r^2) and carries
I_j / pdf_j = f_j(x) / p_j(x), and the run divides by N.

Reuse samples x from all F positions, n paths each (position k: path ids
k n .. k n + n - 1, so every random number is still a pure function of
(seed, path id)). The multi-sample balance-heuristic estimator (Veach's
thesis, section 9.2) with n_k = n is

    sum_k (1/n) sum_{i from k} w_kj(x_i) f_j(x_i) / p_k(x_i),
    w_kj(x) = p_k(x) / sum_l p_l(x),

and every term is f_j(x_i) / (n sum_l p_l(x_i)) whatever position k drew
x_i: a frame's estimate is

    (1/n) sum_{all F n paths} f_j(x_i) / D(x_i),   D = sum_l p_l,

unbiased wherever f_j > 0 implies D > 0, which holds because f_j > 0
implies p_j > 0 (the spot emits only where its pdf is positive; V and
the side enter f_j and p_j alike). Written as photon powers:

    f_j / D = (I_j / pdf_j) (p_j / D) = P_j(x) w_ij,  w_ij = p_j / D <= 1,

where P_j(x) is the power an ordinary photon from y_j towards x carries
(the emitter's record power times the spot's profile, in units of
phi_max). The stored tail of path i carries its own photon's power
P_k(w_ki) T_b (T_b: the tail's throughput after b bounces); scaled by
P_j(x_i) w_ij / P_k(w_ki) it carries P_j(x_i) w_ij T_b: the tail of a
photon of power P_j w_ij.

So frame j is an ordinary batch of F n paths, path i's segment 0 from
y_j to x_i with power P_j(x_i) w_ij and its tail so scaled, resolved as a
run of n photons (not F n: the 1/n of the estimator above).

The bound. Every power stays <= 1 (phi_max), the fixed-point argument of
kernels/oclgi_types.h: P_j <= 1 and w_ij <= 1 (the balance heuristic's
weights over p_j/D, and D >= p_j). The "F" a normalised balance heuristic
would put in the weight (F w_ij can reach F) is what resolving as n
instead of F n photons folds into the scale. A frame's sum has F n x
max_depth contributions, each at most 2^24 units: F n is held to
MAX_PHOTONS (2^31) and max_depth to 256, as for any run, so sums stay
below 2^63. (Float rounding of the scale can exceed 1 by ulps; the bound
has a factor 2 to spare.)

What is not reused: a path whose segment 0 escapes has no first hit, and
a path whose first hit position j cannot see, or sees from the other side,
contributes nothing to frame j (f_j = 0 there). Visibility of all F
positions from every first hit is traced once (F - 1 shadow rays per
path, one bit each: its own position hit it); a frame traces no ray.
A DETP disc reaching past a surface's edge can catch escaping segments of
an ordinary run that reuse leaves out: query points within the radius of
an open edge (the Cornell box's front) differ by that light.

Parameters (:class:`LightReuse`)
--------------------------------
==============  ==============================================================
engine          an :class:`oclgi.Engine` of a diffuse scene whose only
                emitter is the moving light
light           the light's name (``name`` in its scene-file table) or its
                index among the scene's point and spot lights (point lights
                first, as the scene holds them)
positions       (F, 3) world positions, one per frame
directions      (F, 3) spot axes (None: the light's own, every frame)
photons         paths traced from each position, n (default: the scene's
                photon count / F)
seed            the run's seed (default: the scene's)
max_depth       segments per path (default: the scene's)
batch_paths     paths per batch fed to an estimator (results do not depend on it)
==============  ==============================================================
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pyopencl as cl

from .. import params as params_mod
from ..cl.constants import BSDF_DIFFUSE, EMITTER_POINT, EMITTER_SPOT
from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError
from ..params import MAX_LENGTH
from .photon_trace import PathBatch, PhotonTracer
from .run import SEGMENT_BYTES, Estimate, Stats
from .run import batch_paths as default_batch

__all__ = ["LightReuse", "find_light", "light_path"]


def find_light(scene, light):
    """(index among the scene's point and spot lights, the light) for a name or an index."""
    from ..scene.lights import PointLight, SpotLight, all_lights

    movable = [x for x in all_lights(scene) if isinstance(x, (PointLight, SpotLight))]
    names = [x.name for x in movable if getattr(x, "name", None)]
    if isinstance(light, str):
        hits = [i for i, x in enumerate(movable) if getattr(x, "name", None) == light]
        if not hits:
            raise OclgiError(f"--light {light!r}: no point or spot light of that name in {scene.name!r} "
                             f"(named: {', '.join(map(repr, names)) or 'none'})")
        if len(hits) > 1:
            raise OclgiError(f"--light {light!r}: {len(hits)} lights of {scene.name!r} have that name")
        return hits[0], movable[hits[0]]
    if isinstance(light, bool) or not isinstance(light, (int, np.integer)) or not 0 <= light < len(movable):
        raise OclgiError(f"--light: expected a light's name or an index below {len(movable)} (the scene's point "
                         f"and spot lights), got {light!r}")
    return int(light), movable[int(light)]


def _rows(spec, where: str) -> np.ndarray:
    if isinstance(spec, (str, Path)) and str(spec).lower().endswith(".npy"):
        from ..io import read_npy

        path = Path(spec)
        if not path.is_file():
            raise OclgiError(f"{where} {str(spec)!r}: no such file")
        return np.asarray(read_npy(path, "light positions"), np.float64)
    if isinstance(spec, str):
        try:
            rows = [[float(v) for v in row.split(",")] for row in spec.strip().strip(";").split(";")]
        except ValueError:
            raise OclgiError(f"{where}: expected x,y,z[,dx,dy,dz];... or a .npy file, got {spec!r}") from None
        if len({len(r) for r in rows}) != 1:
            raise OclgiError(f"{where}: every position needs as many numbers, got {spec!r}")
        return np.asarray(rows, np.float64)
    try:
        return np.asarray(spec, np.float64)
    except (TypeError, ValueError):
        raise OclgiError(f"{where}: expected an (F, 3) or (F, 6) array of numbers") from None


def light_path(spec, frames: int | None = None, where: str = "--light-path"):
    """(positions (F, 3), directions (F, 3) or None) from ``spec``: a
    ``.npy`` file, text ``x,y,z;x,y,z;...`` (6 numbers a row: a spot's
    position and axis), or an array. With ``frames``, the rows are
    keyframes interpolated linearly over that many frames (as ``animate
    --path`` does; directions renormalised); without, one row a frame."""
    keys = _rows(spec, where)
    if keys.ndim != 2 or keys.shape[1] not in (3, 6) or len(keys) == 0:
        raise OclgiError(f"{where}: expected rows of 3 (x,y,z) or 6 (x,y,z,dx,dy,dz) numbers, got shape "
                         f"{keys.shape}")
    if not np.isfinite(keys).all() or np.abs(keys[:, :3]).max() > MAX_LENGTH:
        raise OclgiError(f"{where}: positions must be finite and within {MAX_LENGTH:.0e}")
    if frames is not None:
        if frames < 1:
            raise OclgiError(f"--frames must be at least 1, got {frames}")
        u = np.linspace(0, len(keys) - 1, frames) if frames > 1 else np.zeros(1)
        keys = np.stack([np.interp(u, np.arange(len(keys)), keys[:, c]) for c in range(keys.shape[1])], axis=1)
    positions = keys[:, :3]
    if keys.shape[1] == 3:
        return positions, None
    d = keys[:, 3:]
    norm = np.linalg.norm(d, axis=1)
    if not (norm > 0).all():
        raise OclgiError(f"{where}: a direction is zero (row {int(np.argmin(norm)) + 1})")
    return positions, d / norm[:, None]


class LightReuse:
    """The store of one light animation and its frames (module docstring)."""

    def __init__(self, engine, light, positions, directions=None, photons=None, seed=None, max_depth=None,
                 batch_paths: int | None = None):
        self.engine, self.queue = engine, engine.queue
        c = self.compiled = engine.compiled
        self.light_index, self.light = find_light(engine.scene, light)
        positions, dirs = light_path(positions if directions is None else
                                     np.hstack([np.asarray(positions, np.float64),
                                                np.asarray(directions, np.float64)]), None, "positions")
        self.positions, self.directions = positions, dirs
        self.frames = len(positions)
        self._check_scene()
        kind = int(c.emitters_host["kind"][0])
        if dirs is not None and kind != EMITTER_SPOT:
            raise OclgiError("directions are a spot light's; this light is a point light")
        settings = engine.scene.settings
        n = settings.photons // self.frames if photons is None else photons
        self.paths_per_position = params_mod.photons(max(1, n), "photons per light position")
        total = self.frames * self.paths_per_position
        params_mod.photons(total, "paths of the animation (frames x photons per position)")
        self.seed = settings.seed if seed is None else seed
        self.max_depth = settings.max_depth if max_depth is None else max_depth
        self.params = engine.run_params(photons=self.paths_per_position, seed=self.seed, max_depth=self.max_depth)
        self.seed, self.max_depth = self.params.seed, self.params.max_depth
        self.batch = params_mod.photons(batch_paths or default_batch(engine.batch_bytes, self.max_depth, total),
                                        "paths per batch")
        self.batch = min(self.batch, total)
        self.n_paths = total
        limit = self.queue.device.max_mem_alloc_size
        if total * self.max_depth * SEGMENT_BYTES > limit:
            raise OclgiError(f"{self.frames} positions x {self.paths_per_position:,} paths of up to "
                             f"{self.max_depth} segments need more than one device buffer holds "
                             f"({limit / 2**30:.2f} GiB); give fewer photons or frames")
        recs = np.repeat(c.emitters_host[:1], self.frames)
        recs["p"] = self.positions
        if dirs is not None:
            recs["e1"] = dirs
        self.records = recs
        ctx = self.queue.context
        mf = cl.mem_flags
        self.lights = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=recs)
        self.words = (self.frames + 31) // 32
        self.seconds = {}
        self._prog = programs(ctx).get("light_reuse")
        self._trace()
        self._weights()
        self.frame_segments = cl.Buffer(ctx, mf.READ_WRITE, self.batch * self.max_depth * SEGMENT_BYTES)
        self.frame_len = cl.Buffer(ctx, mf.READ_WRITE, self.batch * 4)

    def _check_scene(self) -> None:
        c, scene = self.compiled, self.engine.scene
        kinds = c.emitters_host["kind"]
        if c.n_emitters != 1 or int(kinds[0]) not in (EMITTER_POINT, EMITTER_SPOT):
            raise OclgiError(f"{scene.name}: light reuse moves the scene's only emitter, a point or spot light; "
                             f"this scene has {c.n_emitters} emitters")
        if not np.max(self.light.power) > 0:  # then the scene's one emitter is another light
            raise OclgiError(f"{scene.name}: the light to move has no power; light reuse moves the scene's only "
                             "emitter")
        bad = sorted({m.name for m in scene.materials if m.kind != "diffuse" or max(m.emission) > 0})
        if bad or (c.materials_host["kind"] != BSDF_DIFFUSE).any():
            raise OclgiError(f"{scene.name}: light reuse needs diffuse, non-emitting surfaces; not so: "
                             f"{', '.join(map(repr, bad))}")

    # -- the store: traced once ---------------------------------------------------
    def _trace(self) -> None:
        """n paths from each position k, ids k n .., into one store."""
        t0 = time.perf_counter()
        ctx, md = self.queue.context, self.max_depth
        self.store = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, self.n_paths * md * SEGMENT_BYTES)
        self.store_len = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, self.n_paths * 4)
        n = self.paths_per_position
        step = min(self.batch, n)
        tracer = _PositionTracer(self.queue, self.compiled, self.seed, md, step, self.engine.local_size)
        one = cl.Buffer(ctx, cl.mem_flags.READ_ONLY, self.records.itemsize)
        tracer.emitters = one
        self.segments = 0
        lens = np.empty(step, np.int32)
        for k in range(self.frames):
            cl.enqueue_copy(self.queue, one, self.records[k:k + 1])
            for a in range(0, n, step):
                m = min(step, n - a)
                first = k * n + a
                batch = tracer.trace(first, m)
                cl.enqueue_copy(self.queue, self.store, batch.segments, byte_count=m * md * SEGMENT_BYTES,
                                dst_offset=first * md * SEGMENT_BYTES)
                cl.enqueue_copy(self.queue, self.store_len, batch.path_len, byte_count=m * 4, dst_offset=first * 4)
                cl.enqueue_copy(self.queue, lens[:m], batch.path_len)
                self.segments += int(lens[:m].sum())
        self.queue.finish()
        self.seconds["trace"] = time.perf_counter() - t0

    def _weights(self) -> None:
        t0 = time.perf_counter()
        c, ctx = self.compiled, self.queue.context
        self.density_sum = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, self.n_paths * 4)
        self.visible = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, self.n_paths * self.words * 4)
        launch(self.queue, self._prog.reuse_weights, self.n_paths, *c.scene_args, c.tri_normals, self.lights,
               c.emitter_cdf, self.frames, self.paths_per_position, self.store, self.n_paths, self.max_depth, c.eps, self.words,
               self.density_sum, self.visible, local_size=self.engine.local_size)
        self.queue.finish()
        self.seconds["weights"] = time.perf_counter() - t0

    # -- frames -------------------------------------------------------------------
    def batches(self, frame: int, tails: bool = True):
        """Frame ``frame``'s F n paths as PathBatches of at most ``batch_paths``
        (one reused buffer: use each before asking for the next); ``tails``
        False: segment 0 alone, the direct light (for studies)."""
        self._check_frame(frame)
        c = self.compiled
        for first in range(0, self.n_paths, self.batch):
            m = min(self.batch, self.n_paths - first)
            launch(self.queue, self._prog.reuse_frame, m, c.tri_normals, self.lights, c.emitter_cdf, int(frame),
                   self.paths_per_position, int(bool(tails)), self.store, self.store_len, self.density_sum, self.visible,
                   self.words, first, m, self.max_depth, self.frame_segments, self.frame_len,
                   local_size=self.engine.local_size)
            yield PathBatch(self.frame_segments, self.frame_len, first, m, self.max_depth)

    def _check_frame(self, frame) -> None:
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or not 0 <= frame < self.frames:
            raise OclgiError(f"frame must be an index below {self.frames}, got {frame!r}")

    def estimator(self, points, method=None, radius=None, extension=None, count_emitted=None, **options):
        """A fresh estimator for this animation's frames (``Engine.estimator``
        with the run's parameters: n photons, for the resolve)."""
        from .. import queries

        if not isinstance(points, queries.QueryPoints):  # an (n, 6) array, as Engine.irradiance takes
            a = queries.real_array(points, "points")
            if a.ndim != 2 or a.shape[1] != 6:
                raise OclgiError(f"points must be an (n, 6) array of x y z nx ny nz, got shape {a.shape}")
            points = queries.from_arrays(a[:, :3], a[:, 3:])
        self.run_params = self.engine.run_params(method, self.paths_per_position, radius, self.seed,
                                                 self.max_depth, extension, count_emitted)
        return self.engine.estimator(points, self.run_params, **options)

    def estimate(self, frame: int, estimator, reweighting=None) -> Estimate:
        """Frame ``frame`` accumulated into ``estimator`` (its sums reset to
        what it held when made) and resolved: the irradiance with the light
        at ``positions[frame]``. ``reweighting``: a Reweighting of this
        animation over ``estimator`` (oclgi/tracing/light_reweight.py): the
        tails' sums by their stored pairs, the same bits."""
        if not hasattr(estimator, "_reuse_empty"):
            estimator._reuse_empty = estimator.state()
        estimator.restore(estimator._reuse_empty)
        t0 = time.perf_counter()
        if reweighting is not None:
            if reweighting.reuse is not self or reweighting.estimator is not estimator.summing:
                raise OclgiError("the re-weighting belongs to another animation or estimator")
            self._check_frame(frame)
            reweighting.accumulate(frame)
        else:
            for batch in self.batches(frame):
                estimator.accumulate(batch)
        self.queue.finish()
        t1 = time.perf_counter()
        scale = self.compiled.fixed_scale(self.paths_per_position)
        with self.light_at(frame):  # a resolve that reads the lights (direct = "exact") sees the frame's
            device = estimator.resolve(scale)
            irr = read_buffer(self.queue, device, (estimator.n, 4), np.float32)
        t2 = time.perf_counter()
        p = getattr(self, "run_params", self.params)
        stats = Stats(photons=self.paths_per_position, segments=self.segments, points=estimator.n, method=p.method,
                      radius=float(p.radius or 0.0))
        stats.seconds = {"frame": t1 - t0, "resolve": t2 - t1}
        out = Estimate(irr[:, :3], estimator.accumulators(), scale, stats, estimator.points, estimator.work(),
                       estimator)
        out.device_irradiance = device  # float4 per point, for Engine.shade (until the next frame)
        return out

    def frames_irradiance(self, points, method=None, radius=None, **options) -> list[Estimate]:
        """Every frame's Estimate at ``points`` (one estimator, reset per frame)."""
        est = self.estimator(points, method, radius, **options)
        return [self.estimate(j, est) for j in range(self.frames)]

    # -- recomputation, for comparison and free moves --------------------------------
    @contextmanager
    def light_at(self, frame: int):
        """A context in which the engine's light stands at position
        ``frame`` (every ordinary run and render sees it there): a frame
        recomputed from scratch, what reuse is measured against."""
        frame, c = int(frame), self.compiled
        cl.enqueue_copy(self.queue, c.emitters, self.records[frame:frame + 1])
        try:
            yield self.engine
        finally:
            cl.enqueue_copy(self.queue, c.emitters, np.ascontiguousarray(c.emitters_host))
            self.queue.finish()


class _PositionTracer(PhotonTracer):
    """photon_trace.cl with the light's record of one position in place of the scene's."""

    emitters = None

    def _trace_args(self) -> tuple:
        args = list(super()._trace_args())
        return tuple(self.emitters if a is self.compiled.emitters else a for a in args)
