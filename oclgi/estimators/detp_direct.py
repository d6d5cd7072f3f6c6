"""Exact direct light for DETP (the option ``direct = "exact"`` of every DETP
variant; the kernel is kernels/detp_direct.cl).

Why. A DETP disc reads the mean irradiance over the disc (DESIGN.md 3).
Where the irradiance jumps within the disc, that mean is not the point's:
the sharp shadow of a point light or the sun cuts through a disc, and a
point in shadow reads the light beside it (or a lit point the shadow
beside it). On the generated foliage (bench/complex_accuracy.py) every
leaf point that adaptive radii left off by 2x was of this kind: 22-39% of
a disc of 0.1 d sunlit around a point in shadow, or 82% shadowed around a
lit one (Mitsuba's irradiance averaged over those discs agrees with DETP's
estimate). No radius rule can see such an edge at the pilot's density,
and a disc small enough to stay clear of it is too noisy. The direct
light needs no disc at all: shadow rays give it at the point itself (the
split of direct and indirect light that photon mapping has always made).

What. With ``direct = "exact"``:

- the segments leaving the lights do not count (as ``count_emitted =
  false``): the discs estimate the indirect light only;
- the resolve adds, at each point, the direct irradiance of every light:
  for delta lights (point, spot, IES, sun) exactly, one shadow ray each:
  I(d) cos(theta) / r^2 (I the photons' own intensity, profile included),
  E cos(theta) for the sun; for area lights, a uniform sky and an
  environment map by ``direct_samples`` pairs of a light sample and a
  cosine (BSDF) sample (default: photons / sqrt(4096 x points) of the run,
  from 16 to 65,536, see ``default_samples``; with ``gather = N`` each hit
  takes max(1, direct_samples // N)),
  combined by multiple importance sampling
  (``direct_mis``: "power", the default, or "balance" heuristic; "light"
  or "bsdf" alone, for studies). The light sample picks an emitter by its
  power (a binary search in a CDF: a scene with 10^4 emitting triangles
  costs no more per sample than one with 1), a point uniform on the
  triangle, a direction of the sky uniform, or a texel of the map by its
  luminance tables; stratified over an s x s grid.

Bias traded: none for the direct part (exact for delta lights; unbiased,
with noise falling as 1 / sqrt(direct_samples), for the others; up to the
shadow ray's offset of eps along the normal, the tracer's own); the
indirect part keeps the disc's.

Invariants. The direct term depends on the point (position and normal),
the lights, the pose and the run's seed only: its random numbers are
keyed by a hash of the point's bits, not its index, so it is the same for
every variant, batch split, work-group size, subset of points (a
session's layers, MPI ranks), and it is recomputed at every resolve, so a
session's irradiance after moves equals a fresh session's at the final
pose. The sums (``accumulators``) are those of ``count_emitted = false``.

Cost: one shadow ray per point and delta light, and 2 ``direct_samples``
rays per point when the scene has other lights, at each resolve.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.programs import launch, programs
from ..errors import OclgiError
from ..params import integral

DIRECT_MODES = ("photons", "exact")
# The multiple importance sampling of the lights that are not deltas; the
# order is kernels/detp_direct.cl's ``mis`` argument.
MIS_MODES = ("power", "balance", "light", "bsdf")
DIRECT_SAMPLES = 16  # pairs of samples per point of an estimator built without a run's photon count
MAX_SAMPLES = 65536
# The default with a run (Engine.estimator) spends the time where the error
# is. A point's variance is about A / photons + B / S (the discs' noise and
# the light samples'), the time c_p photons + c_d points S; the least
# variance for a given time takes S = photons / sqrt(K points), K = (A / B)
# (c_d / c_p). Measured at 256 points, 5 x 10^6 photons, adaptive radii and
# gather 1024 (bench/README.md, "Accuracy"): K = 1,140 in the courtyard under
# a sky (the sky seen through an opening: light samples are noisy), 3,810
# under the foliage's area light, 20,700 in the Cornell box; K = 4096 is
# their geometric mean, and missing a scene's own K by 4x costs little (the
# optimum is flat). Sensor sets (hundreds of points) get thousands of pairs,
# images (10^5 points and more) tens.
BALANCE = 4096
MIN_DEFAULT = 16


def default_samples(photons: int, points: int) -> int:
    """The pairs of light and cosine samples per point a run of ``photons``
    over ``points`` query points takes by default (see BALANCE): a function
    of the whole request, so a session's layers, MPI ranks and batches of a
    run all take the same."""
    s = round(int(photons) / np.sqrt(BALANCE * max(int(points), 1)))
    return int(min(max(s, MIN_DEFAULT), MAX_SAMPLES))


def hit_samples(samples: int, n_rays: int) -> int:
    """A gather hit's share of its point's samples (at least one pair): the
    point's indirect light averages its N hits, and their noise with it."""
    return max(1, int(samples) // int(n_rays))


def check(direct, samples=DIRECT_SAMPLES, mis="power") -> bool:
    """Whether ``direct`` asks for the exact direct light; one error line for a bad value."""
    if not isinstance(direct, str) or direct not in DIRECT_MODES:
        raise OclgiError(f"direct must be one of {', '.join(map(repr, DIRECT_MODES))}, got {direct!r}")
    n = integral(samples)
    if n is None or not 1 <= n <= MAX_SAMPLES:
        raise OclgiError(f"direct_samples must be an integer from 1 to {MAX_SAMPLES}, got {samples!r}")
    if not isinstance(mis, str) or mis not in MIS_MODES:
        raise OclgiError(f"direct_mis must be one of {', '.join(map(repr, MIS_MODES))}, got {mis!r}")
    return direct == "exact"


class DirectLight:
    """Every light's direct irradiance, added to a DETP resolve's output
    (see the module's docstring)."""

    def __init__(self, queue, compiled, count_emitted: bool, local_size: int | None = None,
                 samples: int = DIRECT_SAMPLES, mis: str = "power", seed: int = 0):
        if not count_emitted:
            raise OclgiError("direct 'exact' adds the direct light that count_emitted = false leaves out: "
                             "give one of them")
        check("exact", samples, mis)
        self.queue, self.compiled, self.local_size = queue, compiled, local_size
        self.samples, self.mis = int(samples), MIS_MODES.index(mis)
        seed = int(seed)
        self.seed = (np.uint32(seed & 0xFFFFFFFF), np.uint32((seed >> 32) & 0xFFFFFFFF))
        self.kernel = programs(queue.context).get("detp_direct").detp_direct_add

    def add(self, positions: cl.Buffer, normals: cl.Buffer, n: int, irradiance: cl.Buffer) -> None:
        """irradiance[i].xyz += the direct irradiance at point i (at the current pose)."""
        c = self.compiled
        launch(self.queue, self.kernel, n, *c.scene_args, c.emitters, c.emitter_cdf, c.spread_info, c.spread_cdf,
               c.spread_ids, np.int32(c.n_spread), c.tri_emitter, np.int32(c.sky_emitter), c.background,
               c.background_texels, np.int32(self.mis), np.int32(c.n_emitters), c.emitter_bound, positions,
               normals, np.int32(n), np.float32(c.eps), np.int32(self.samples), *self.seed, irradiance,
               local_size=self.local_size)
