"""DETP with disc indexing (García et al. 2006, "Density estimation
optimizations for global illumination", WSCG; DESIGN.md section 3).

Plain DETP loops over discs and, for each, over every segment: O(n_R n_P).
Disc indexing transposes the loop: a BVH is built once over the discs'
bounding boxes (the query points do not change between batches), and every
segment of a batch walks it, testing only the discs of the leaves whose box
it meets. With discs that do not overlap much, a segment meets about
cbrt(n_P) of them, so the cost is about ``u n_R cbrt(n_P)`` (u the cost of a
segment-disc test) instead of ``u n_R n_P``.

Algorithm:

1. Discs: centre x, unit normal n, radius d (the run's, or the point's own
   with ``radius_mode="adaptive"``, oclgi/estimators/adaptive_radius.py,
   carried in the blocks as d^2). Its box has half-extent
   ``d sqrt(1 - n_a^2)`` on axis a, plus a pad (below). Points with a zero
   normal (camera rays that missed) can never be crossed and are left out.
2. ``build_bvh`` (oclgi/accel/bvh_build.py, host numpy, Morton order) over
   the boxes; each leaf's discs are stored as blocks of 8 float8 lanes
   (``oclgi.cl.layout.DiscBlock``, kernels/detp_disc_index.cl), so a leaf is
   tested the way ``detp_plain`` tests 8 points.
3. The binary tree is collapsed into 8-wide nodes (oclgi/accel/box_wide.py:
   the scene tree's grouping, 8 child boxes per node in float8 lanes).
4. Per batch, one work-item per path walks the tree with each segment
   (kernels/box_wide.h: one float8 slab test meets a node's 8 children,
   and every child met is pushed), applies DETP_TEST (kernels/detp.h, the one
   definition shared with plain DETP) to the discs of each leaf met, and
   adds the segment's fixed-point power to every disc it crosses with 64-bit
   ``atom_add``. Sums are integers, so the result is identical to plain DETP
   bit for bit, whatever the order.

Exactness needs the culling to be conservative: every segment that DETP_TEST
accepts must reach the disc's leaf. The crossing point o + (num / w.n) w of
a segment accepted in float32 lies within a few float32 ulps (of the
coordinates) of the exact disc: measured below 1e-7 of the scene's size,
for grazing and rim crossings alike. So boxes are padded by ``PAD`` (2e-5)
times the scene's coordinate scale, two orders of magnitude more, and
rounded outward to float32; tests/test_detp_disc_index.py fails when the
boxes are shrunk by 1e-6 of it.
Escaping segments (t_end = inf) are clipped by the slab test itself: the
root box bounds every disc.

Parameters:

==============  =========  ====================================================
option          default    meaning
==============  =========  ====================================================
``leaf_size``   32         discs per BVH leaf (1 to 256), tested 8 per float8 block
``builder``     ``lbvh``   ``lbvh`` (Morton order, fast to build) or ``sah``
                           (binned SAH, oclgi/accel/bvh_sah.py: slower to build,
                           fewer nodes visited per segment)
==============  =========  ====================================================

plus the DETP parameters of :class:`oclgi.estimators.base.DetpEstimator`.

Why 32: in float8 lanes a segment-disc test costs a few ns, a node visit
(scalar slab test and stack) tens of ns (measured on PoCL, Cornell box,
10^5 discs), so fewer, fuller leaves win although they raise u.

A session (oclgi/incremental/session.py) builds its static points' tree
once and walks it on every move: it asks for ``SESSION_TREE`` instead, a
SAH tree with 64 discs a leaf, which the build costs more for and every
move gains from (Sponza, 10^5 discs, a move's change pass, alternating in
one run: Morton/32 27.5 ms, SAH/32 25.6 ms, SAH/64 24.3 ms; the build 0.05
s against 0.19 s). One pass over a whole batch does not repay it. Its
dynamic points' tree (``DYNAMIC_TREE``), built on the host on every move
and walked once, keeps the Morton order with 64 discs a leaf (Sponza's
3,836 dynamic points, alternating in one run: the walk 8.54 -> 8.28 ms,
the build 3.19 -> 2.87 ms against 32 a leaf).

A session's static points also keep, from each move to the next, the
discs every new segment crossed (``list_crossings``, kernels/
detp_disc_index.cl ``detp_disc_index_change``): a small object's moves
re-trace mostly the same paths again, and the next move takes their old
suffixes away by these lists instead of walking the tree (Sponza, a bunny
going round: 60% of the old suffixes' segments; the change pass 26.0 ->
23.7 ms). The lists hold at most ``LISTED_PER_PATH`` ids a path and
``LISTED_IDS`` in all (a segment that does not fit is walked next time);
they are dropped with the store or the discs, and not made when work is
counted (the counts measure the walks).

Scaling (counted, tests/test_detp_disc_index.py): with discs spread through
the volume, u per segment grows as n_P^0.33; with discs on the surfaces it
stays flat (a segment only meets the discs near its two ends), so cbrt(n_P)
is the volume case's law and an upper trend for surfaces.

Memory: the tree and the disc blocks, O(n_P); a session's lists, the
crossings of one move's new segments; nothing of size n_R x n_P.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from ..accel.box_wide import MAX_LEAF, collapse_boxes
from ..accel.boxes import PAD, active_discs, check_depth, coordinate_scale, disc_boxes, leaf_blocks
from ..accel.bvh_build import BUILDERS, build_bvh
from ..cl.layout import DiscBlock
from ..cl.programs import launch
from ..errors import OclgiError
from .adaptive_radius import AdaptiveRadii
from .base import DetpEstimator

# The static points' tree of a session: built once, walked on every move
SESSION_TREE = {"builder": "sah", "leaf_size": 64}
# Its dynamic points' tree: built on the host on every move, walked once
DYNAMIC_TREE = {"leaf_size": 64}
# A move's crossing lists (accumulate_change): at most this many disc ids
# per re-traced path, and in all (a move of every path gets fewer each)
LISTED_PER_PATH = 192
LISTED_IDS = 1 << 24


class DetpDiscIndex(DetpEstimator):
    name = "detp_disc_index"
    fuses_with_find = True  # the find pass sums its discs (kernels/update.cl), or accumulate_listed does
    radii_maker = AdaptiveRadii  # each disc block carries its discs' d^2

    session_tree = SESSION_TREE  # what a session's static points are built with (module doc)
    dynamic_tree = DYNAMIC_TREE  # and its dynamic points
    # accumulate_change lists the discs each new segment crosses, and sums
    # the next move's old suffixes from the lists (a session's static
    # points, which live as long as it; Session sets it)
    list_crossings = False

    def __init__(self, queue, compiled, points, radius: float, leaf_size: int = 32, builder: str = "lbvh", **kw):
        super().__init__(queue, compiled, points, radius, **kw)
        if (isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer))
                or not 1 <= leaf_size <= MAX_LEAF):
            raise OclgiError(f"leaf_size must be an integer from 1 to {MAX_LEAF}, got {leaf_size!r}")
        if builder not in BUILDERS:
            raise OclgiError(f"builder must be one of {', '.join(map(repr, BUILDERS))}, got {builder!r}")
        self.leaf_size = int(leaf_size)
        self._crossings, self._no_list = None, None
        self.builder = builder
        prog = self.program("detp_disc_index")
        self.k_walk, self.k_change = prog.detp_disc_index, prog.detp_disc_index_change
        self.build_index()

    def build_index(self):
        """The BVH over the discs and their blocks (host numpy, then uploaded)."""
        t0 = time.perf_counter()
        self._crossings = None  # lists of crossings belong to the discs they were made with
        points = self.points
        ids = active_discs(points)
        self.n_active = len(ids)
        self.nodes = None
        if self.n_active:
            pos, nrm = points.positions[ids, :3], points.normals[ids, :3]
            pad = PAD * coordinate_scale(self.compiled, pos)
            lo, hi = disc_boxes(pos, nrm, self.radii[ids], pad)
            bvh = build_bvh(lo, hi, self.leaf_size, quality=self.builder, queue=self.queue)
            check_depth(bvh.depth, "discs")
            nodes, blk, lane, n_blocks = leaf_blocks(bvh.nodes, self.n_active)
            blocks = np.zeros(n_blocks, DiscBlock)  # padding lanes: zero normal
            o = bvh.order
            for c, (x, n) in enumerate((("x", "nx"), ("y", "ny"), ("z", "nz"))):
                blocks[x][blk, lane] = pos[o, c]
                blocks[n][blk, lane] = nrm[o, c]
            blocks["r2"][blk, lane] = self.radius2[ids[o]]
            blocks["id"][blk, lane] = ids[o]
            self.root_box = (nodes["lo"][0].astype(np.float64), nodes["hi"][0].astype(np.float64))
            wide = collapse_boxes(nodes, "discs")
            nodes, self.depth = wide.nodes, wide.depth
            self.nodes = self.upload(nodes)
            self.blocks = self.upload(blocks)
            self.n_nodes = len(nodes)
        self.build_seconds = time.perf_counter() - t0

    def points_changed(self) -> None:
        """Points moved (a camera session's dynamic points): index them again."""
        self.build_index()

    @property
    def sums_changes(self) -> bool:
        """Can ``accumulate_change`` stand for a move's two suffix passes?
        Not with surface-consistent counting: its test has a second bound
        that depends on the segment's length."""
        return "consistent_span" not in self.defines

    def accumulate_change(self, old, store, affected):
        """A move's update after the re-trace (kernels/detp_disc_index.cl
        detp_disc_index_change): the old suffixes ``old`` (the gathered
        batch, power times -1) taken away and the new ones (``store``'s
        paths ``affected``) added, the common part of each suffix's first
        segment skipped; equal to ``accumulate(old)`` plus ``accumulate``
        of the new suffixes bit for bit."""
        if self.nodes is None or not len(affected):
            return
        n = len(affected)
        if self._no_list is None:
            self._no_list = self.zeros(8)
        none = self._no_list
        if self.list_crossings and not self.count_work:  # work counts measure the walks
            c = self._crossings
            if c is None or c["batch"] is not store:  # a new store: nothing listed yet
                at = self.upload(np.full(2 * store.n_paths, -2, np.int32))  # (generation, entry) per path
                c = self._crossings = {"batch": store, "at": at, "runs": none, "ids": none,
                                       "replayed": self.zeros(8)}
            cap = int(min(LISTED_PER_PATH, LISTED_IDS // n))
            mf = cl.mem_flags  # written by the kernel before any read
            runs = cl.Buffer(self.ctx, mf.READ_WRITE, 8 * n * store.max_depth)
            ids = cl.Buffer(self.ctx, mf.READ_WRITE, 4 * max(n * cap, 1))
            args = (c["at"], store.retraced, c["runs"], c["ids"], runs, ids, cap, c["replayed"])
            c["runs"], c["ids"] = runs, ids  # the next move's lists (kept until then)
        else:
            args = (none, -1, none, none, none, none, 0, none)
        launch(self.queue, self.k_change, n, self.nodes, self.blocks, old.segments, store.segments,
               affected.paths_buf, affected.starts_buf, n, store.max_depth, self.count_emitted, self.ext,
               self.acc, self.work_buf, *args, local_size=self.local_size)

    def forget_store(self, store) -> None:
        """``store`` is gone (a session resized or re-traced it): its crossing
        lists are of no use to the next store, and must not keep it alive."""
        if self._crossings is not None and self._crossings["batch"] is store:
            self._crossings = None

    def replayed(self) -> int:
        """Segments ``accumulate_change`` has summed from lists so far (for
        the current store; 0 without lists)."""
        if self._crossings is None:
            return 0
        out = np.zeros(1, np.uint64)
        cl.enqueue_copy(self.queue, out, self._crossings["replayed"])
        return int(out[0])

    def accumulate_listed(self, store, listed, n: int):
        """``accumulate`` over the paths ``listed[:n]`` (a device int32
        buffer of path indices) of the batch ``store`` only, each segment
        culled by the tree's root box first (kernels/detp_disc_index.cl)."""
        if self.nodes is None or not n:
            return
        self._walk(store, listed, n, cull=True)

    def accumulate(self, batch):
        if self.nodes is None:
            return
        self._walk(batch, None, batch.n_paths, cull=False)

    def _walk(self, batch, listed, n: int, cull: bool):
        """detp_disc_index over ``n`` paths of ``batch``: its first n, or those ``listed``."""
        lo, hi = (np.append(b, 0.0).astype(np.float32) for b in self.root_box)  # float32 values: exact
        launch(self.queue, self.k_walk, n, self.nodes, self.blocks, batch.segments, listed, n, batch.max_depth,
               self.count_emitted, self.ext, int(cull), lo, hi, self.acc, self.work_buf, local_size=self.local_size)
