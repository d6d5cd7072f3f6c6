"""What the page draws at each vertex, and the frames that bring it up to date.

A vertex's colour is its outgoing radiance, linear RGB:
``L = Le + rho * E / pi`` with ``rho`` the diffuse part of its source
triangle's material (Material.diffuse_albedo) and ``Le`` its emission; the
page applies the exposure and sRGB. Textures and mesh vertex colours are
not sampled: a textured surface shows its material's albedo (the solution
itself, the irradiance, does not depend on that choice).

A frame carries only what the page does not have yet, as float16 (half the
bytes of float32; the page widens them with typed-array sets). A float16 keeps 11 significant bits, a relative step
of 2^-11 (0.05%), finer than an 8-bit sRGB code anywhere on the display's
scale; its range (2^-24 to 65504) is kept on the radiance by a power-of-two
scale 2^e shared by every vertex, which the page folds into its exposure:
e puts the largest colour near 2^12, four stops below float16's largest,
and is chosen again (a whole frame) only when a colour would overflow, so
HDR light keeps 40 stops above float16's smallest subnormal. RGBE or uint8
with a shared exposure would save bytes, not range or precision the
display can show. The page holds ``half(colour * 2^-e)``, bit for bit.

The vertices whose halves changed go as runs of consecutive indices (start,
length; the page copies each with one typed-array set), a changed vertex
alone as an index (a run would cost twice its bytes), or the whole array
when that is smaller. A frame is of one mesh: the tessellation (level 0)
or one of its levels of detail (oclgi/viewer/level_of_detail.py, level k
>= 1, whose colours are a fixed averaging of the tessellation's); each
level has an encoder of its own, so a page holds every level's halves as
they were last sent. Layout, little-endian:

    b"OGVC", uint32 seq, uint32 mode (FULL 0 | SPARSE 1), int32 e, uint32 level,
    FULL:   uint32 V, float16 rgb[V][3]   (V: the level's vertices)
    SPARSE: uint32 R, uint32 S, uint32 start[R], uint32 length[R], uint32 single[S],
            float16 rgb[sum(length) + S][3]   (the runs' vertices in order, then the singles')
"""

from __future__ import annotations

import math
import struct

import numpy as np

MAGIC = b"OGVC"
FULL, SPARSE = 0, 1
HEADER = struct.Struct("<4sIIiI")
HEADROOM = 12  # the largest colour near 2^12 after scaling
HALF_MAX = 65504.0  # float16's largest: a colour above it at the current scale means a new scale


def vertex_terms(scene, vertex_tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rho / pi, Le) per vertex, float32 (V, 3), from each vertex's source triangle's material."""
    mats = scene.materials
    reflect = np.array([m.diffuse_albedo for m in mats], np.float64) / math.pi
    emit = np.array([m.emission for m in mats], np.float64)
    mat = np.asarray(scene.tri_material)[vertex_tri]
    return reflect[mat].astype(np.float32), emit[mat].astype(np.float32)


def radiance(irradiance: np.ndarray, terms: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Outgoing radiance (V, 3) float32 from the per-vertex irradiance."""
    reflect, emit = terms
    return (emit + reflect * np.asarray(irradiance, np.float32)).astype(np.float32)


def scale_exponent(colours: np.ndarray) -> int:
    """e such that the largest finite colour times 2^-e lies in [2^(HEADROOM-1), 2^HEADROOM) (0 when all are 0)."""
    finite = colours[np.isfinite(colours)]
    top = float(finite.max()) if finite.size else 0.0
    if top <= 0:
        return 0
    return int(np.clip(math.frexp(top)[1] - HEADROOM, -100, 100))


def to_half(colours: np.ndarray, e: int) -> np.ndarray:
    """The float16 the page holds for ``colours`` at scale 2^e (rounded to nearest even)."""
    return np.ldexp(np.asarray(colours, np.float32), -e).astype(np.float16)


def runs(changed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start, length) of the runs of consecutive indices in sorted ``changed``."""
    if not len(changed):
        return changed, changed
    breaks = np.nonzero(np.diff(changed) != 1)[0] + 1
    starts = np.concatenate([[0], breaks])
    lengths = np.diff(np.concatenate([starts, [len(changed)]]))
    return changed[starts], lengths


class FrameEncoder:
    """The halves the page has of one level, and the frame that brings it to new colours."""

    def __init__(self, n_vertices: int, level: int = 0):
        self.sent = None  # the float16 bits the page has (None: nothing yet)
        self.e = 0  # the scale's exponent the page has
        self.n = n_vertices
        self.level = level
        self.seq = None  # the update the page's halves are of

    def frame(self, colours: np.ndarray, seq: int) -> bytes | None:
        """The frame from the colours sent to ``colours``; ``colours`` become
        the colours sent. When no half changed: None if the page's halves
        are of update ``seq`` already, else a frame of no colour (the page
        learns they are current at ``seq``, which it needs to know which of
        its levels is up to date)."""
        colours = np.ascontiguousarray(colours, np.float32)
        e = self.e
        if self.sent is None or colours.max(initial=0.0) * 2.0 ** -e > HALF_MAX:
            e = scale_exponent(colours)
        half = to_half(colours, e).view(np.uint16)
        if self.sent is None or e != self.e:
            changed = np.arange(self.n)
        else:
            ne = half != self.sent
            changed = np.nonzero(ne[:, 0] | ne[:, 1] | ne[:, 2])[0]  # (numpy's any(axis=1) is ten times slower)
            if not len(changed) and seq == self.seq:
                return None
        self.sent, self.e, self.seq = half, e, seq
        start, length = runs(changed)
        alone = length == 1
        sparse = 4 * (2 + 2 * (~alone).sum() + alone.sum()) + 6 * len(changed)
        if sparse >= 4 + 6 * self.n:
            return (HEADER.pack(MAGIC, seq, FULL, e, self.level) + struct.pack("<I", self.n)
                    + half.astype("<u2").tobytes())
        long_, singles = ~alone, start[alone]
        order = np.concatenate([changed[~np.repeat(alone, length)], singles])
        return (HEADER.pack(MAGIC, seq, SPARSE, e, self.level) + struct.pack("<II", long_.sum(), len(singles))
                + start[long_].astype("<u4").tobytes() + length[long_].astype("<u4").tobytes()
                + singles.astype("<u4").tobytes() + half[order].astype("<u2").tobytes())
