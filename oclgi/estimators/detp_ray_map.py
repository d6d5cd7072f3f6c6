"""DETP with a ray map (Havran, Bittner, Herzog, Seidel 2005, "Ray maps for
global illumination", EGSR; DESIGN.md section 3).

The other transposition of plain DETP's O(n_R n_P) loop: index the
**segments** of a batch and query the index with every disc. Per batch:

1. Read the batch's segments to the host. Keep the slots that count (not
   empty; bounce >= 1 when ``count_emitted`` is off) and clip each segment
   [0, t_end + e] to the box that bounds every (padded) disc: escaping
   segments have t_end = inf, and a segment that misses that box crosses no
   disc and is dropped.
2. Cut each clipped segment into pieces no longer than ``piece`` times the
   scene's diagonal (at most 64 per segment, and on average at most 4 per
   segment of a batch, the length growing if needed, so memory stays
   O(n_R)). A segment's box is as long as the segment, so without pieces a
   segment across the scene is met by every disc under it; the original's
   kd-tree clips segments to its cells for the same reason. Piece j spans
   the parameters [e_j, e_j+1] (float32 edges) and *claims* the crossings
   whose t = num / (w.n) lies in [e_j, e_j+1), the first and last ranges
   open to -inf and +inf: a partition of the line, and every piece keeps the
   whole segment's o and w, so all compute the same t and exactly one piece
   counts a crossing.
3. ``build_bvh`` (host numpy, Morton order) over the pieces' boxes, padded
   like the disc boxes (:mod:`oclgi.estimators.detp_disc_index`), leaves of
   at most ``leaf_size`` (<= 32) pieces stored as blocks of 8 float8 lanes
   (``oclgi.cl.layout.PieceBlock``, kernels/detp_ray_map.cl).
4. One work-item per disc walks the tree with the disc's padded box
   (kernels/box_bvh.h), applies DETP_TEST (kernels/detp.h, shared with plain
   DETP) and the claim to the pieces of each leaf met, and adds the crossing
   segments' fixed-point powers to its own sums: no atomics. Identical to
   plain DETP bit for bit.

The original builds its kd-tree lazily, refining only the nodes that queries
reach; here the whole BVH is built eagerly for each batch on the host (a
vectorised Morton build, about 0.5 s per million boxes), which is simpler
and leaves the device to the queries. That build is the ray map's main cost
once segments are cut (the walk is fast, the build is O(pieces) host work),
so ``build_seconds`` (host) and ``query_seconds`` (device) are kept apart.

Parameters:

==============  =========  ====================================================
option          default    meaning
==============  =========  ====================================================
``leaf_size``   32         pieces per BVH leaf, 1..32 (the original's 32)
``piece``       0.1        longest piece, as a fraction of the scene's
                           diagonal; 0 keeps segments whole
==============  =========  ====================================================

plus the DETP parameters of :class:`oclgi.estimators.base.DetpEstimator`.
Memory: per batch, the pieces' boxes, blocks and tree (O(n_R), at most 4
pieces per segment on average); per estimator, the disc records (O(n_P));
nothing of size n_R x n_P.
"""

from __future__ import annotations

import time

import numpy as np

from ..accel.boxes import PAD, active_discs, check_depth, coordinate_scale, disc_boxes, leaf_blocks
from ..accel.bvh_build import build_bvh, morton_codes
from ..cl.constants import LANES
from ..cl.layout import PieceBlock, RayMapDisc
from ..cl.programs import launch
from ..errors import OclgiError
from .base import DetpEstimator

MAX_LEAF = 32
MAX_PIECES = 64  # pieces per segment, at most
PIECE_BUDGET = 4  # pieces per segment of a batch, on average at most (memory)


def clip_segments(org, dirs, tmax, lo, hi, tmin=0.0):
    """Parameter interval [enter, leave] of each segment o + t w, tmin <= t <=
    tmax, inside the box [lo, hi] (float64); enter > leave when it misses."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dirs
        t0 = (lo - org) * inv
        t1 = (hi - org) * inv
    # w_a = 0: the slab is all or nothing; 0 * inf gives NaN, which fmin/fmax drop
    enter = np.maximum(np.fmax.reduce(np.fmin(t0, t1), axis=1), tmin)
    leave = np.minimum(np.fmin.reduce(np.fmax(t0, t1), axis=1), tmax)
    return enter, leave


def piece_counts(enter, leave, length: float) -> np.ndarray:
    """Pieces per segment [enter, leave]: at most MAX_PIECES, none longer
    than ``length`` (0: segments whole), the length growing until there are
    at most PIECE_BUDGET per segment on average (memory O(segments))."""
    n = len(enter)
    k = np.ones(n, np.int64)
    while length > 0:
        k = np.clip(np.ceil((leave - enter) / length), 1, MAX_PIECES).astype(np.int64)
        if k.sum() <= PIECE_BUDGET * n:
            break
        length *= 1.25 * k.sum() / (PIECE_BUDGET * n)
    return k


def cut_pieces(enter, leave, k):
    """Segment [enter, leave] cut into k equal pieces: (segment of each
    piece, its float32 edges t_a and t_b, the t it claims from claim_lo to
    claim_hi). Piece j spans [e_j, e_j+1] (e_0 = enter, e_k = leave) and
    claims the t in [e_j, e_j+1), the outer edges opened to -inf and +inf:
    a partition of the line, so one piece claims each crossing."""
    seg = np.repeat(np.arange(len(k), dtype=np.int64), k)
    start = np.zeros(len(k), np.int64)
    np.cumsum(k[:-1], out=start[1:])
    j = np.arange(len(seg)) - start[seg]
    step = (leave - enter) / k
    t_a = (enter[seg] + j * step[seg]).astype(np.float32)
    t_b = np.empty_like(t_a)
    t_b[:-1] = t_a[1:]
    t_b[start + k - 1] = leave.astype(np.float32)  # the last piece ends at leave
    claim_lo = np.where(j == 0, np.float32(-np.inf), t_a)
    claim_hi = np.where(j + 1 == k[seg], np.float32(np.inf), t_b)
    return seg, t_a, t_b, claim_lo, claim_hi


class DetpRayMap(DetpEstimator):
    name = "detp_ray_map"

    def __init__(self, queue, compiled, points, radius: float, leaf_size: int = MAX_LEAF,
                 piece: float = 0.1, **kw):
        super().__init__(queue, compiled, points, radius, **kw)
        if isinstance(leaf_size, bool) or not isinstance(leaf_size, (int, np.integer)) or \
                not 1 <= leaf_size <= MAX_LEAF:
            raise OclgiError(f"leaf_size must be an integer in 1..{MAX_LEAF}, got {leaf_size!r}")
        self.leaf_size = int(leaf_size)
        if isinstance(piece, bool) or not isinstance(piece, (int, float, np.floating)) or not piece >= 0:
            raise OclgiError(f"piece must be a number >= 0 (0: segments are not cut), got {piece!r}")
        self.piece_length = float(piece) * compiled.scene.diagonal
        self.k_query = self.program("detp_ray_map").detp_ray_map
        self.build_seconds = 0.0  # host: read back, clip, cut, build the BVH, pack
        self.query_seconds = 0.0  # device: the walk of every disc
        self.pieces = self.indexed = 0  # pieces in the maps, segments they come from
        self.set_discs()

    def set_discs(self):
        """The disc records, in Morton order, and the box bounding them all."""
        points = self.points
        ids = active_discs(points)
        self.n_active = len(ids)
        if not self.n_active:
            return
        pos, nrm = points.positions[ids, :3], points.normals[ids, :3]
        self.pad = PAD * coordinate_scale(self.compiled, pos)
        lo, hi = disc_boxes(pos, nrm, self.radius, self.pad)
        # Every crossing point lies in some padded disc box, hence in this
        # box padded once more: segments are clipped to it.
        self.bound_lo = lo.min(axis=0).astype(np.float64) - self.pad
        self.bound_hi = hi.max(axis=0).astype(np.float64) + self.pad
        # Discs in Morton order: neighbouring work-items walk the same nodes.
        c = 0.5 * (lo.astype(np.float64) + hi)
        o = np.argsort(morton_codes(c, c.min(axis=0), c.max(axis=0)), kind="stable")
        discs = np.zeros(self.n_active, RayMapDisc)
        discs["x"], discs["id"], discs["n"] = pos[o], ids[o], nrm[o]
        discs["lo"], discs["hi"] = lo[o], hi[o]
        self.discs = self.upload(discs)

    def points_changed(self) -> None:
        """Points moved (a camera session's dynamic points): new disc records."""
        self.set_discs()

    def build(self, batch):
        """The ray map of a batch: (nodes, blocks, number of pieces indexed), or None."""
        segs = batch.read_segments(self.queue)
        keep = (segs["dir"] != 0).any(axis=1)
        if not self.count_emitted:
            keep[::batch.max_depth] = False  # bounce 0: the segments leaving the lights
        slots = np.nonzero(keep)[0].astype(np.int32)
        s = segs[slots]
        org, w = np.ascontiguousarray(s["org"]), np.ascontiguousarray(s["dir"])
        tmax = s["t_end"] + np.float32(self.ext)  # float32 sum, as the kernels
        enter, leave = clip_segments(org.astype(np.float64), w.astype(np.float64), tmax.astype(np.float64),
                                     self.bound_lo, self.bound_hi)
        met = np.nonzero(enter <= leave)[0]
        if not len(met):
            return None
        slots, s, org, w, enter, leave = slots[met], s[met], org[met], w[met], enter[met], leave[met]
        # Long segments cut into pieces of at most piece_length, each claiming its own range of t.
        k = piece_counts(enter, leave, self.piece_length)
        self.pieces += int(k.sum())
        self.indexed += len(slots)
        seg, t_a, t_b, claim_lo, claim_hi = cut_pieces(enter, leave, k)
        # Boxes in float32: the rounding of o + t w (a few ulps of the
        # coordinates) is far below the pad.
        o_s, w_s = org[seg], w[seg]
        p0 = o_s + t_a[:, None] * w_s
        p1 = o_s + t_b[:, None] * w_s
        pad = np.float32(self.pad)
        lo = np.minimum(p0, p1) - pad
        hi = np.maximum(p0, p1) + pad
        del p0, p1
        bvh = build_bvh(lo, hi, self.leaf_size)
        del lo, hi
        check_depth(bvh.depth, "segments")
        n = len(seg)
        nodes, blk, lane, n_blocks = leaf_blocks(bvh.nodes, n)
        # Piece records (a row of PieceBlock's fields, the slot's int bits as
        # a float) in leaf order, scattered to their lanes, then turned into
        # PieceBlocks (each field a lane vector).
        nf = len(PieceBlock.names)
        col = {name: k for k, name in enumerate(PieceBlock.names)}
        rec = np.empty((n, nf), np.float32)
        for a, axis in enumerate("xyz"):
            rec[:, col["o" + axis]], rec[:, col["w" + axis]] = o_s[:, a], w_s[:, a]
        rec[:, col["t_end"]] = s["t_end"][seg]
        rec[:, col["slot"]] = slots[seg].view(np.float32)
        rec[:, col["claim_lo"]], rec[:, col["claim_hi"]] = claim_lo, claim_hi
        lanes = np.zeros((n_blocks * LANES, nf), np.float32)  # padding lanes: w = 0
        row = np.dtype((np.void, rec.itemsize * nf))  # whole records: much faster to move
        lanes.view(row).ravel()[blk * LANES + lane] = rec.view(row).ravel()[bvh.order]
        del rec
        blocks = np.empty(n_blocks, PieceBlock)
        blocks.view(np.float32).reshape(n_blocks, nf, LANES)[:] = lanes.reshape(n_blocks, LANES, nf).transpose(0, 2, 1)
        return self.upload(nodes), self.upload(blocks), n

    def accumulate(self, batch):
        if not self.n_active:
            return
        t0 = time.perf_counter()
        built = self.build(batch)
        t1 = time.perf_counter()
        self.build_seconds += t1 - t0
        if built is None:
            return
        nodes, blocks, _ = built
        launch(self.queue, self.k_query, self.n_active, nodes, blocks, self.discs, self.n_active, batch.segments,
               self.radius**2, self.ext, self.acc, self.work_buf, local_size=self.local_size)
        self.queue.finish()  # the tree's buffers are released when this returns
        self.query_seconds += time.perf_counter() - t1
        for buf in (nodes, blocks):
            buf.release()
