"""Every segment of every path, kept on the device, and the steps of an
incremental update over it (DESIGN.md section 4; kernels/update.cl).

A store is traced once: ``photons`` paths of up to ``max_depth`` segments,
path-major, as one batch. After a movable object moves:

1. ``find`` lists, per path, the first segment that hit the object at its
   old pose or meets it at its new pose (the earlier segments are the same
   in the moved scene). Only paths whose cell mask (kernels/update.cl: the
   cells of a grid of at most 122 cells over the scene that the path crosses, and
   the faces it leaves the grid through) meets the cells of the object's old and new
   boxes are examined: a few percent of the store for a small object,
   instead of every stored segment;
2. ``suffixes(affected, -1)`` gathers the affected suffixes with negated
   power into a scratch batch: accumulated by an estimator, they take their
   old contributions away exactly (fixed-point sums);
3. ``retrace(affected)`` re-traces the suffixes in place, with the same code
   and random numbers as a full trace;
4. ``suffixes(affected, +1)`` gathers the new suffixes, to be added; or a
   disc-indexed estimator reads them from the store itself and sums the
   old and new suffixes in one pass (``DetpDiscIndex.accumulate_change``:
   a suffix's old and new first segments share origin, direction and
   power, and the discs both cross cancel, so that part is skipped; a
   path the last move re-traced has its old segments' discs listed, and
   they are summed from the lists);
5. ``sum_near(discs)`` sums the moved store into a camera session's
   dynamic points, reading only the paths whose cell masks meet their
   discs' box (the list of a ``find`` given a ``near`` box that holds it).

Sessions (oclgi/incremental/session.py) drive these steps for their estimators.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyopencl as cl
from pyopencl import cltypes

from ..cl.constants import CELL_OUTSIDE_BIT as OUTSIDE_BIT
from ..cl.layout import Segment
from ..cl.programs import launch, programs
from ..errors import OclgiError
from ..tracing.photon_trace import PathBatch, PhotonTracer

MAX_CELLS = OUTSIDE_BIT  # cells of the paths' masks (kernels/update.cl: 128 bits, the last six for the faces)
CANDIDATE_CHUNK = 64  # paths per work-item of the mask scan (kernels/update.cl update_candidates)


def grid_dims(extent) -> np.ndarray:
    """Cells per axis, at most MAX_CELLS in all, as near cubic as they go
    (5 x 5 x 4 for a cube, 7 x 4 x 4 for Sponza's atrium): the axis with the
    longest cells is split once more while the cells still fit."""
    e = np.asarray(extent, np.float64)
    dims = np.ones(3, np.int64)
    while True:
        a = int(np.argmax(e / dims))
        grown = dims.copy()
        grown[a] += 1
        if np.prod(grown) > MAX_CELLS:
            return dims
        dims = grown


@dataclass
class Affected:
    """Paths a move touches: ids and first affected bounce, on host and device."""

    paths: np.ndarray  # int32, path ids
    starts: np.ndarray  # int32, first affected bounce of each
    paths_buf: cl.Buffer | None = None
    starts_buf: cl.Buffer | None = None

    def __len__(self):
        return len(self.paths)


class SuffixCount:
    """A count of segments on its way from the device: ``int()`` waits for it."""

    def __init__(self, lengths: np.ndarray, event):
        self.lengths, self.event = lengths, event

    def __int__(self) -> int:
        if self.event is not None:
            self.event.wait()
        return int(self.lengths.sum())


def _holds(outer, inner) -> bool:
    """Does box ``outer`` (lo, hi) hold box ``inner``?"""
    return bool((np.asarray(outer[0]) <= inner[0]).all() and (np.asarray(inner[1]) <= outer[1]).all())


class SegmentStore:
    """``photons`` paths traced with ``seed`` and ``max_depth`` on the engine's scene.

    ``first``: the global id of the first stored path (a rank of a
    distributed session stores ids first .. first + photons - 1; path k of
    the store is global path first + k). ``total``: the run's photon count,
    which fixes the scale of the sums (default ``photons``). ``copy``: a
    store of the same engine, seed and depth whose first paths this one
    takes instead of tracing them (``resized``)."""

    def __init__(self, engine, photons: int, seed: int, max_depth: int, first: int = 0, total: int | None = None,
                 copy: "SegmentStore | None" = None):
        self.engine, self.queue = engine, engine.queue
        self.photons, self.max_depth, self.first_path = int(photons), int(max_depth), int(first)
        self.total = self.photons if total is None else int(total)
        nbytes = self.photons * self.max_depth * Segment.itemsize
        limit = engine.queue.device.max_mem_alloc_size
        if nbytes > limit:
            raise OclgiError(f"a session keeps every segment: {self.photons:,} paths x {self.max_depth} slots "
                             f"need {nbytes / 2**30:.2f} GiB, more than one device allocation "
                             f"({limit / 2**30:.2f} GiB); use fewer photons or a smaller max_depth")
        self.nbytes = nbytes
        self.scale = engine.compiled.fixed_scale(self.total)
        self.seed = int(seed)
        self.tracer = PhotonTracer(self.queue, engine.compiled, seed, max_depth, self.photons, engine.local_size)
        # retrace() finds a path's random numbers by the batch's path_offset
        self.added = None  # the paths traced here that ``copy`` did not hold (resized hands them over)
        self.added_paths = 0  # how many there were
        if copy is None:
            self.batch = self.tracer.trace(self.first_path, self.photons)
        else:
            self.batch = self._take(copy)
        prog = programs(engine.ctx).get("update")
        self.k_first, self.k_gather = prog.update_first_affected, prog.update_gather
        self.k_cells, self.k_candidates = prog.update_path_cells, prog.update_candidates
        self.k_lengths = prog.update_suffix_lengths
        mf = cl.mem_flags
        self.first = cl.Buffer(engine.ctx, mf.READ_WRITE, self.photons * 4)
        self.first_host = np.empty(self.photons, np.int32)
        self.scratch = None  # grown on demand: gathered suffixes
        self.examined = 0  # paths the last find looked at
        self._near = None  # (box, listed paths, count) of the last find's ``near``
        # the cell grid: the scene as loaded, padded; the cells' pad is far
        # above float rounding, so a segment meeting a box inside a cell
        # always meets the padded cell
        lo, hi = (np.asarray(b, np.float64) for b in engine.compiled.bounds)
        diag = float(np.linalg.norm(hi - lo)) or 1.0
        self.pad = 1e-4 * diag
        self.grid_lo = lo - 0.01 * diag
        self.dims = grid_dims(hi - lo + 0.02 * diag)
        self.cell = (hi - lo + 0.02 * diag) / self.dims
        self.all_paths = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                   hostbuf=np.arange(self.photons, dtype=np.int32))
        self.cells = cl.Buffer(engine.ctx, mf.READ_WRITE, self.photons * 16)
        self.candidates = cl.Buffer(engine.ctx, mf.READ_WRITE, self.photons * 4)
        self.count = cl.Buffer(engine.ctx, mf.READ_WRITE, 4)
        self._mark_cells(self.all_paths, self.photons)
        # each movable object's world box when the stored paths were traced
        inst = engine.compiled.instances_host
        self.boxes = {k: (inst["lo"][k].astype(np.float64), inst["hi"][k].astype(np.float64))
                      for k in range(len(inst))}

    def _take(self, other: "SegmentStore") -> PathBatch:
        """Paths 0 .. photons - 1: those ``other`` holds copied on the device,
        the rest traced (the same segments a full trace gives, path by path:
        randomness is a function of the path id)."""
        kept = min(self.photons, other.photons)
        t = self.tracer
        slot = self.max_depth * Segment.itemsize
        cl.enqueue_copy(self.queue, t.segments, other.batch.segments, byte_count=kept * slot)
        cl.enqueue_copy(self.queue, t.path_len, other.batch.path_len, byte_count=kept * 4)
        if self.photons > kept:
            extra = PhotonTracer(self.queue, self.engine.compiled, self.seed, self.max_depth, self.photons - kept,
                                 self.engine.local_size)
            self.added = extra.trace(self.first_path + kept, self.photons - kept)
            cl.enqueue_copy(self.queue, t.segments, self.added.segments, dst_offset=kept * slot,
                            byte_count=(self.photons - kept) * slot)
            cl.enqueue_copy(self.queue, t.path_len, self.added.path_len, dst_offset=kept * 4,
                            byte_count=(self.photons - kept) * 4)
        return PathBatch(t.segments, t.path_len, self.first_path, self.photons, self.max_depth)

    def resized(self, photons: int) -> tuple["SegmentStore", PathBatch | None]:
        """A store of paths 0 .. photons - 1 at the current pose, without
        tracing the paths this one holds; and what changes in the sums: the
        paths it adds (a batch to accumulate), or the paths it drops (their
        segments with negated power, a batch of this store's to accumulate
        before it goes), or None. Whole-run stores only."""
        if self.first_path != 0 or self.total != self.photons:
            raise OclgiError("a store of part of a run's paths (a rank's) cannot change its photon count")
        new = SegmentStore(self.engine, photons, self.seed, self.max_depth, copy=self)
        if photons > self.photons:
            # the paths added, as a batch of their own for the caller to sum; not kept by the store,
            # whose own buffers hold them too (kept, they doubled a grown session's memory)
            added, new.added = new.added, None
            new.added_paths = added.n_paths
            return new, added
        if photons < self.photons:
            dropped = np.arange(photons, self.photons, dtype=np.int32)
            mf = cl.mem_flags
            gone = Affected(dropped, np.zeros(len(dropped), np.int32),
                            cl.Buffer(self.engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=dropped),
                            cl.Buffer(self.engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                      hostbuf=np.zeros(len(dropped), np.int32)))
            return new, self.suffixes(gone, -1.0)
        return new, None

    # -- reading ------------------------------------------------------------
    def segments(self) -> np.ndarray:
        """The stored segments (``Segment`` array, path-major), on the host."""
        return self.batch.read_segments(self.queue)

    def path_len(self) -> np.ndarray:
        return self.batch.read_path_len(self.queue)

    # -- updating -----------------------------------------------------------
    def _mark_cells(self, paths: cl.Buffer, n: int):
        f4 = lambda v: np.array([*v, 0.0], np.float32)  # noqa: E731
        launch(self.queue, self.k_cells, n, self.batch.segments, self.batch.path_len, self.max_depth,
               paths, n, f4(self.grid_lo), f4(self.cell), cltypes.make_int4(*(int(d) for d in self.dims), 0),
               self.pad, self.cells)

    def _region(self, boxes) -> np.ndarray | None:
        """The 128-bit mask (two uint64) of the cells the boxes meet, padded,
        with the bit of each face of the grid a box reaches past; None to
        examine every path (a box that is not finite)."""
        dims = self.dims
        grid_hi = self.grid_lo + dims * self.cell
        bits = 0
        for lo, hi in boxes:
            lo, hi = lo - self.pad, hi + self.pad
            if not np.isfinite([lo, hi]).all():
                return None
            for axis in range(3):
                if lo[axis] < self.grid_lo[axis]:
                    bits |= 1 << (OUTSIDE_BIT + 2 * axis)
                if hi[axis] > grid_hi[axis]:
                    bits |= 1 << (OUTSIDE_BIT + 2 * axis + 1)
            c0 = np.floor((lo - self.grid_lo) / self.cell).astype(np.int64)
            c1 = np.floor((hi - self.grid_lo) / self.cell).astype(np.int64)
            if (c1 < 0).any() or (c0 >= dims).any():
                continue  # wholly outside the grid
            c0, c1 = np.clip(c0, 0, dims - 1), np.clip(c1, 0, dims - 1)
            for z in range(c0[2], c1[2] + 1):
                for y in range(c0[1], c1[1] + 1):
                    for x in range(c0[0], c1[0] + 1):
                        bits |= 1 << int(x + dims[0] * (y + dims[1] * z))
        return np.array([bits & (2**64 - 1), bits >> 64], np.uint64)

    def _list_candidates(self, boxes) -> tuple[cl.Buffer | None, int]:
        """The paths whose cell masks meet the boxes' cells (``_region``),
        listed on the device in any order, and their count; (None, 0) when
        every path must be examined."""
        region = self._region(boxes)
        if region is None:
            return None, 0
        q = self.queue
        count = np.zeros(1, np.int32)
        cl.enqueue_copy(q, self.count, count)
        chunk = CANDIDATE_CHUNK
        launch(q, self.k_candidates, -(-self.photons // chunk), self.cells, self.photons, chunk,
               cltypes.make_ulong2(*(int(w) for w in region)), self.count, self.candidates)
        cl.enqueue_copy(q, count, self.count)
        return self.candidates, int(count[0])

    def sum_near(self, discs) -> None:
        """Sum the stored segments into the points of ``discs`` (a
        DetpDiscIndex), reading only the paths whose cell masks meet the
        discs' box: a segment that crosses a disc meets its box, inside
        the root box, so its path's mask (current after ``retrace``) meets
        the box's cells, or leaves the grid where the box does. When the
        last ``find`` was given a ``near`` box holding the discs' box, its
        list serves: it held every path whose mask met that box before the
        move, and every path the move re-traced (so whatever its mask is
        now). Otherwise the paths are listed here."""
        if discs.nodes is None:
            return
        if self._near is not None and _holds(self._near[0], discs.root_box):
            _, listed, n = self._near
        else:
            listed, n = self._list_candidates([discs.root_box])
        self._near = None
        if listed is None:
            discs.accumulate(self.batch)
        else:
            discs.accumulate_listed(self.batch, listed, n)

    def find(self, obj: int, discs=None, near=None) -> Affected:
        """Paths touched by the move of object ``obj`` (already placed at its
        new pose). With ``discs`` (a DetpDiscIndex) the same pass also sums
        the stored segments into its points' accumulators: every segment of
        the paths examined, which holds every segment that can reach them.
        ``near`` (a box (lo, hi), float64): the paths examined also include
        those whose masks meet it, and the list is kept for a ``sum_near``
        after the update over discs inside it (one scan of the masks per
        move instead of two; the discs need not exist yet)."""
        engine, q = self.engine, self.queue
        inst = engine.compiled.instances_host
        new_box = (inst["lo"][obj].astype(np.float64), inst["hi"][obj].astype(np.float64))
        fused = discs is not None and discs.nodes is not None
        boxes = [self.boxes[obj], new_box] + ([discs.root_box] if fused else []) + \
            ([near] if near is not None else [])
        self.boxes[obj] = new_box
        listed, n = self._list_candidates(boxes)
        candidates = None
        if listed is None:
            n, listed = self.photons, self.all_paths
        else:
            candidates = np.empty(n, np.int32)  # read with the results below
        self.examined = n
        self._near = None if near is None else (near, listed, n)
        if n:
            args = (*engine.compiled.scene_args, obj, self.batch.segments, listed, n, self.max_depth, self.first)
            if not fused:
                launch(q, self.k_first, n, *args, None, None, 0, 0,
                       None, None, local_size=engine.local_size)
            else:
                k = programs(engine.ctx).get("update", **discs.defines).update_first_affected
                launch(q, k, n, *args, discs.nodes, discs.blocks, discs.count_emitted,
                       discs.ext, discs.acc,
                       discs.work_buf, local_size=engine.local_size)
            # the list with the results (pyopencl waits for a dropped event: held until then)
            pending = None if candidates is None else cl.enqueue_copy(q, candidates, listed, is_blocking=False)
            cl.enqueue_copy(q, self.first_host[:n], self.first)
            del pending
        hit = np.nonzero(self.first_host[:n] >= 0)[0]
        paths, starts = (hit if candidates is None else candidates[hit]).astype(np.int32), self.first_host[hit]
        if candidates is not None:  # listed in any order: the affected paths in order of their ids
            order = np.argsort(paths, kind="stable")
            paths, starts = paths[order], starts[order]
        affected = Affected(paths, starts.copy())
        if len(paths):
            mf = cl.mem_flags
            affected.paths_buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=affected.paths)
            affected.starts_buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=affected.starts)
        return affected

    def suffix_count(self, affected: Affected) -> "SuffixCount":
        """Stored segments in the affected suffixes (n_Rec of this update)
        as the store holds them when the device gets here: enqueued, read
        without waiting, summed by ``int()`` (a move's statistics stay off
        its critical path)."""
        n = len(affected)
        if not n:
            return SuffixCount(np.zeros(0, np.int32), None)
        out = cl.Buffer(self.engine.ctx, cl.mem_flags.WRITE_ONLY, n * 4)
        launch(self.queue, self.k_lengths, n, self.batch.path_len, affected.paths_buf, affected.starts_buf, n, out)
        host = np.empty(n, np.int32)
        return SuffixCount(host, cl.enqueue_copy(self.queue, host, out, is_blocking=False))

    def suffixes(self, affected: Affected, sign: float) -> PathBatch:
        """The affected suffixes, power times ``sign``, as a batch of
        len(affected) paths; the slots before each suffix are holes."""
        n = len(affected)
        nbytes = n * self.max_depth * Segment.itemsize
        if self.scratch is None or self.scratch.size < nbytes:
            # grow geometrically, never past the store itself
            size = max(nbytes, min(2 * (self.scratch.size if self.scratch else 0), self.nbytes))
            self.scratch = cl.Buffer(self.engine.ctx, cl.mem_flags.READ_WRITE, size)
        launch(self.queue, self.k_gather, n, self.batch.segments, self.max_depth, affected.paths_buf,
               affected.starts_buf, n, sign, self.scratch)
        # Path ids stay in the gathered slots; the scratch is a batch like any other.
        return PathBatch(self.scratch, self.batch.path_len, 0, n, self.max_depth)

    def retrace(self, affected: Affected):
        """Re-trace the affected suffixes in place (the scene already moved)
        and bring their cell masks up to date."""
        self.tracer.retrace(self.batch, affected.paths_buf, affected.starts_buf, len(affected))
        self._mark_cells(affected.paths_buf, len(affected))
