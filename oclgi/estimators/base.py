"""What every estimator provides, and the parts all DETP variants share.

An estimator is built for one set of query points, then ``accumulate`` is
called once per batch of traced paths (fixed-point sums on the device), and
``resolve`` turns the sums into irradiance. ``work()`` returns the exact work
counts (t segment-sphere tests, u segment-disc tests, BVH node visits) when
the estimator was built with ``count_work=True`` (kernels/work.h).
"""

from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError
from . import detp_direct, gather_options, radius_options


def work_counts(queue, buf: cl.Buffer) -> dict:
    """The work counters of ``buf`` (kernels/work.h): t, u and nodes."""
    t, u, nodes = (int(x) for x in read_buffer(queue, buf, 3, np.uint64))
    return {"t": t, "u": u, "nodes": nodes}


class Estimator:
    name = ""
    incremental = True  # sums can be updated exactly by adding and subtracting segments
    family = ""  # "detp" for the DETP variants (same sums, different algorithms), else the method's own
    fuses_with_find = False  # sums a store's segments in the update's find pass (kernels/update.cl)
    sums_changes = False  # accumulate_change stands for a move's subtraction and addition passes

    def __init__(self, queue, compiled, points, count_emitted: bool = True,
                 local_size: int | None = None, count_work: bool = False):
        self.queue, self.ctx, self.compiled, self.points, self.n = queue, queue.context, compiled, points, len(points)
        self.count_emitted, self.local_size, self.count_work = bool(count_emitted), local_size, bool(count_work)
        self.defines = {"count_work": 1} if count_work else {}
        self.work_buf = self.zeros(3 * 8)

    def program(self, stem: str):
        return programs(self.ctx).get(stem, **self.defines)

    def zeros(self, nbytes: int) -> cl.Buffer:
        # Copied from host zeros: on PoCL a fill costs ~0.4 ms even for a few
        # bytes, and sessions build small estimators every frame.
        return cl.Buffer(self.ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR,
                         hostbuf=np.zeros(max(nbytes, 8), np.uint8))

    def upload(self, array) -> cl.Buffer:
        array = np.ascontiguousarray(array)
        if array.nbytes == 0:
            array = np.zeros(1, array.dtype)
        return cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)

    def work(self) -> dict | None:
        return work_counts(self.queue, self.work_buf) if self.count_work else None

    @property
    def summing(self):
        """The estimator whose accumulators the segments go to: this one
        (a final gathering's: its hits' discs, FinalGather.inner)."""
        return self

    # The request's query points when the exact direct light's sample count
    # is the default's (set by Engine.estimator): it follows the photons.
    default_direct_points = None

    def extended(self, photons: int) -> None:
        """The run now counts ``photons`` in all (Run.extend): a default the
        photon count sets follows it, so the longer run equals one run of
        the total bit for bit."""
        if self.default_direct_points is not None:
            self.set_direct_samples(detp_direct.default_samples(photons, self.default_direct_points))

    def set_direct_samples(self, samples: int) -> None:
        """The exact direct light's sample pairs per point from the next resolve on."""

    # Sums kept per query point (DETP, Photon Maps) must be recomputed when a
    # point changes; sums kept per triangle (Impact Count) need not.
    sums_per_point = True

    def replace_points(self, index: np.ndarray, new) -> None:
        """Points ``index`` are now ``new`` (QueryPoints): e.g. the pixels that
        see a moved object. Updates the device copies (and any index built
        over the points); the caller recomputes their sums when
        ``sums_per_point``."""
        raise NotImplementedError

    def accumulate(self, batch):
        raise NotImplementedError

    def resolve(self, scale: float) -> cl.Buffer:
        raise NotImplementedError

    def accumulators(self) -> np.ndarray:
        """The int64 sums, one RGB row per point (Impact Count: per triangle)."""
        return read_buffer(self.queue, self.acc, (self.n, 3), np.int64)

    def move_points(self, index: np.ndarray, new) -> None:
        """The points ``index`` replaced by ``new`` on the host and the device
        (what each estimator's replace_points starts with)."""
        self.points.positions[index] = new.positions
        self.points.normals[index] = new.normals
        self.points.barys[index] = new.barys
        cl.enqueue_copy(self.queue, self.positions, self.points.positions)
        cl.enqueue_copy(self.queue, self.normals, self.points.normals)

    def forget_store(self, store) -> None:
        """``store`` is gone (a session resized or re-traced it): drop what
        this estimator kept of it (none does but DetpDiscIndex)."""

    def first_batch(self, paths_done: int, paths_total: int, segments: int) -> None:
        """After a run's first batch (``paths_done`` of ``paths_total``
        paths, ``segments`` segments): refuse a run whose state would
        outgrow the device, or warn of one that will be mostly noise.
        Nothing by default: sums kept per point or triangle do not grow."""

    # -- a run's state (oclgi/tracing/run.py) --------------------------------
    def state(self) -> dict:
        """What the sums of the paths accumulated so far are, on the host:
        the int64 accumulators and the work counters. ``restore`` of it
        gives an estimator that goes on as this one would."""
        return {"acc": self.accumulators(), "work": read_buffer(self.queue, self.work_buf, 3, np.uint64)}

    def restore(self, state: dict) -> None:
        """Take the sums of ``state`` (from ``state()`` of an estimator of
        the same kind over the same points)."""
        self._restore_array(state, "acc", self.accumulators(), self.acc)
        self._restore_array(state, "work", np.zeros(3, np.uint64), self.work_buf)

    def _restore_array(self, state: dict, key: str, like: np.ndarray, buf: cl.Buffer) -> None:
        a = state.get(key)
        if not isinstance(a, np.ndarray) or a.dtype != like.dtype or a.shape != like.shape:
            got = "nothing" if a is None else f"{getattr(a, 'dtype', type(a).__name__)} {getattr(a, 'shape', '')}"
            raise OclgiError(f"run state: {self.name} expects {key!r} as {like.dtype} {like.shape}, got {got}")
        cl.enqueue_copy(self.queue, buf, np.ascontiguousarray(a))


class Wrapping(Estimator):
    """An estimator whose sums are another's (``wrapped``): final
    gathering's are its hits' discs (final_gather.py), an irradiance
    cache's its records' gathering (irradiance_cache.py). The batches, the
    sums, their saved state and the work counts all go to that one."""

    @property
    def wrapped(self) -> Estimator:
        raise NotImplementedError

    @property
    def summing(self):
        return self.wrapped.summing

    def accumulate(self, batch):
        self.wrapped.accumulate(batch)

    def first_batch(self, paths_done: int, paths_total: int, segments: int) -> None:
        self.wrapped.first_batch(paths_done, paths_total, segments)

    def accumulators(self) -> np.ndarray:
        return self.wrapped.accumulators()

    def state(self) -> dict:
        return self.wrapped.state()

    def restore(self, state: dict) -> None:
        self.wrapped.restore(state)

    def work(self) -> dict | None:
        return self.wrapped.work()

    def forget_store(self, store) -> None:
        self.wrapped.forget_store(store)


class DetpEstimator(Estimator):
    """Shared by every DETP variant: the discs, the per-point sums, resolve.

    Parameters: ``radius`` d; ``extension`` e (segments may end up to e past
    the disc's plane and still count; for concave surfaces); ``count_emitted``
    (segments leaving the lights count, i.e. direct light included);
    ``radius_mode`` "fixed" (d for every point) or "adaptive" (a radius per
    point, fixed when the estimator is built, with ``adaptive_k``,
    ``pilot_photons`` and ``radius_min``: oclgi/estimators/adaptive_radius.py;
    variants with a ``radii_maker`` only); ``radii``: with "adaptive",
    the radius of each point given instead of computed (a session's first
    frame's, ``Session.estimator.radii``); ``direct``: "photons" (the
    direct light from the photons' first segments, as the indirect) or
    "exact" (the first segments do not count and the resolve adds the
    direct irradiance by shadow rays: delta lights exactly, the others by
    ``direct_samples`` light and BSDF samples per point combined by
    ``direct_mis``, keyed by the run's ``seed``;
    oclgi/estimators/detp_direct.py); ``gather`` N > 0 with
    ``gather_seed``: final gathering, the discs at the hits of N cosine
    rays per point (oclgi/estimators/final_gather.py, made by
    Engine.estimator); with ``gather_spacing`` s > 1 a render gathers at
    every s-th pixel each way and interpolates the indirect light between
    (oclgi/estimators/irradiance_cache.py). Every variant selects segments
    with ``detp_crosses``/``DETP_TEST`` (kernels/detp.h), so all give the
    same sums, bit for bit.
    """

    family = "detp"

    # Variants whose kernels read each disc's own radius (plain DETP: a
    # per-point buffer; disc indexing: the disc blocks' r2) name the class
    # that makes adaptive radii (adaptive_radius.AdaptiveRadii).
    radii_maker = None

    def __init__(self, queue, compiled, points, radius: float, extension: float = 0.0,
                 radius_mode: str = "fixed", adaptive_k: int = 16, pilot_photons: int = 32768,
                 radius_min: float = 0.25, radii=None, pilot=None, consistent: bool = False,
                 consistent_span: float = 1.0, direct: str = "photons", direct_samples: int = detp_direct.DIRECT_SAMPLES,
                 direct_mis: str = "power", gather: int = 0, gather_seed: int = 0, gather_spacing: int = 1,
                 seed: int = 0, **kw):
        if gather_options.check(gather, gather_seed):
            # the points' discs give way to discs at the hits of their rays: a
            # different estimator over this variant (Engine.estimator makes it)
            raise OclgiError("gather > 0: build the estimator with Engine.estimator (final_gather.FinalGather "
                             f"over {self.name})")
        if gather_options.spacing(gather_spacing) != 1:
            raise OclgiError(f"gather_spacing {gather_spacing!r} interpolates final gathering between pixels: it "
                             f"needs gather = N rays (and direct = 'exact')")
        radius_options.check(radius_mode, adaptive_k, pilot_photons, radius_min)
        exact_direct = detp_direct.check(direct, direct_samples, direct_mis)
        span = radius_options.consistent_span(consistent, consistent_span)
        if radius_mode == "adaptive" and self.radii_maker is None:
            raise OclgiError(f"radius_mode 'adaptive' is offered by detp and detp_disc_index, not {self.name}")
        given = radius_options.given_radii(radii, radius_mode, len(points))
        self.direct = None
        if exact_direct:  # the lights' own segments give way to the shadow rays
            self.direct = detp_direct.DirectLight(queue, compiled, kw.get("count_emitted", True), kw.get("local_size"),
                                                  direct_samples, direct_mis, seed)
            kw = dict(kw, count_emitted=False)
        super().__init__(queue, compiled, points, **kw)
        self.radius = float(radius)
        self.radius_mode = radius_mode
        self.adaptive = None
        if given is not None:
            self.radii = given  # e.g. a session's first frame's: kept as they are
        elif radius_mode == "adaptive":
            if pilot is None:
                raise OclgiError("adaptive radii need the pilot's paths (Engine.estimator traces them)")
            self.adaptive = self.radii_maker(queue, compiled, pilot, self.radius, extension, self.count_emitted,
                                             adaptive_k, radius_min, self.local_size)
        self.set_radii(np.arange(self.n))
        # The user's extension plus a scene-relative tolerance, so segments
        # ending on the disc's own surface survive float rounding.
        self.ext = float(extension) + 10.0 * compiled.eps
        self.consistent = span is not None
        if self.consistent:
            # the build's constant (kernels/detp.h DETP_CONSISTENT): ext plus
            # the span in units of the radius, as a float32 literal
            self.defines = dict(self.defines, consistent_span=f"{float(np.float32(self.ext + span * radius))!r}f")
        self.positions = self.upload(points.positions)
        self.normals = self.upload(points.normals)
        self.acc = self.zeros(self.n * 3 * 8)
        self.irr = self.zeros(self.n * 16)
        # every DETP program carries the resolve kernel (kernels/detp_resolve.h)
        self.k_resolve = self.program(self.name).detp_resolve
        self.k_resolve_radii = self.program(self.name).detp_resolve_radii

    def set_radii(self, index: np.ndarray) -> None:
        """The radii of points ``index`` (all of them when built): d, or the
        adaptive radius of each point (a function of the point alone, so a
        replaced point gets the radius it would have had from the start).
        Kept on the host as float32 d^2 (what the kernels compare with; d^2
        rounded once, as a float argument is) and 1 / d^2 (the resolve's)."""
        if self.radius_mode == "fixed":
            self.radii = np.full(self.n, self.radius)
        elif self.adaptive is not None:
            if not hasattr(self, "radii"):
                self.radii = np.zeros(self.n)
            if len(index):
                self.radii[index] = self.adaptive.radii(self.points.subset(index) if len(index) < self.n
                                                        else self.points)
        self.radius2 = (self.radii**2).astype(np.float32)
        self.radius2_buf = self.upload(self.radius2)
        if self.radius_mode != "fixed":  # the fixed resolve takes one scalar
            self.inv_radius2_buf = self.upload((1.0 / self.radii**2).astype(np.float32))

    def replace_points(self, index: np.ndarray, new) -> None:
        self.move_points(index, new)
        if self.adaptive is not None:
            self.set_radii(np.asarray(index))
        self.points_changed()

    # Fewer segments than this per disc, on average, and most discs catch
    # none: the estimate is noise (relative standard error about 1/sqrt(count)).
    FEW_SEGMENTS = 0.25

    def first_batch(self, paths_done: int, paths_total: int, segments: int) -> None:
        """Warn when the discs are too small for the photons: segments end
        on surfaces about uniformly over the scene's area A, so a disc of
        area pi d^2 catches about (segments of the run) pi d^2 / A."""
        area = float(np.sum(self.compiled.areas, dtype=np.float64))
        if paths_done <= 0 or not area > 0:
            return
        mean_r2 = self.radius**2 if self.radius_mode == "fixed" else float(np.mean(self.radii**2))
        expected = segments / paths_done * paths_total * math.pi * mean_r2 / area
        if expected < self.FEW_SEGMENTS:
            import warnings

            from ..scene.scene import OclgiWarning

            warnings.warn(f"radius {self.radius:.3g}: each disc catches about {expected:.1f} segments of this run "
                          f"on average, so the estimates will be mostly noise; use a larger radius or more "
                          f"photons (about {self.FEW_SEGMENTS / max(expected, 1e-9):.3g} times)", OclgiWarning,
                          stacklevel=4)

    def points_changed(self) -> None:
        """Rebuild whatever the variant built over the points (default: nothing)."""

    def set_direct_samples(self, samples: int) -> None:
        if self.direct is not None:
            self.direct.samples = int(samples)

    def resolve(self, scale: float) -> cl.Buffer:
        """Irradiance (float4 per point, on the device): E = acc / (scale pi d^2),
        plus the lights' direct irradiance with ``direct = "exact"``."""
        if self.radius_mode != "fixed":  # each point's own d: E = acc * (1 / (scale pi)) * (1 / d^2)
            launch(self.queue, self.k_resolve_radii, self.n, self.acc, self.n, 1.0 / (scale * math.pi),
                   self.inv_radius2_buf, self.irr)
        else:
            inv = 1.0 / (scale * math.pi * self.radius**2)
            launch(self.queue, self.k_resolve, self.n, self.acc, self.n, inv, self.irr)
        if self.direct is not None:
            self.direct.add(self.positions, self.normals, self.n, self.irr)
        return self.irr

