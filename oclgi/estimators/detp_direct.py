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
and a disc small enough to stay clear of it is too noisy. Delta lights'
direct irradiance needs no disc at all: one shadow ray per point and
light gives it exactly (the split of direct and indirect light that
photon mapping has always made).

What. With ``direct = "exact"``:

- the segments leaving the lights do not count (as ``count_emitted =
  false``): the discs estimate the indirect light only;
- the resolve adds, at each point, sum over the delta lights of the
  irradiance that arrives unoccluded: I(d) cos(theta) / r^2 for point,
  spot and IES lights (I the photons' own intensity, profile included),
  E cos(theta) for the sun.

Bias traded: none for the direct part (it is exact, up to the shadow ray's
offset of eps along the normal, the tracer's own); the indirect part keeps
the disc's. Only delta lights are lit this way, so a scene with area
lights or a sky is refused (their direct light comes by photons, which
this option turns off).

Invariants. The direct term depends on the points, the lights and the
pose only (no randomness): the same for every variant, batch split and
work-group size, and it is recomputed at every resolve, so a session's
irradiance after moves equals a fresh session's at the final pose. The
sums (``accumulators``) are those of ``count_emitted = false``.

Cost: one shadow ray per point and light, at each resolve.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.constants import EMITTER_IES, EMITTER_POINT, EMITTER_SPOT, EMITTER_SUN
from ..cl.programs import launch, programs
from ..errors import OclgiError

DIRECT_MODES = ("photons", "exact")
DELTA_KINDS = (EMITTER_POINT, EMITTER_SPOT, EMITTER_SUN, EMITTER_IES)


def check(direct) -> bool:
    """Whether ``direct`` asks for the exact direct light; one error line for a bad value."""
    if not isinstance(direct, str) or direct not in DIRECT_MODES:
        raise OclgiError(f"direct must be one of {', '.join(map(repr, DIRECT_MODES))}, got {direct!r}")
    return direct == "exact"


class DirectLight:
    """The delta lights' direct irradiance, added to a DETP resolve's output."""

    def __init__(self, queue, compiled, count_emitted: bool, local_size: int | None = None):
        if not count_emitted:
            raise OclgiError("direct 'exact' adds the direct light that count_emitted = false leaves out: "
                             "give one of them")
        other = sorted({int(k) for k in compiled.emitters_host["kind"] if k not in DELTA_KINDS})
        if other:
            raise OclgiError(f"{compiled.scene.name}: direct 'exact' lights delta lights only (point, spot, IES "
                             "and sun lights); this scene has area lights or a sky, whose direct light "
                             "comes by photons: use direct = 'photons'")
        self.queue, self.compiled, self.local_size = queue, compiled, local_size
        self.kernel = programs(queue.context).get("detp_direct").detp_direct_add

    def add(self, positions: cl.Buffer, normals: cl.Buffer, n: int, irradiance: cl.Buffer) -> None:
        """irradiance[i].xyz += the direct irradiance at point i (at the current pose)."""
        c = self.compiled
        launch(self.queue, self.kernel, n, *c.scene_args, c.emitters, c.n_emitters, c.emitter_cdf, c.emitter_bound,
               positions, normals, n, np.float32(c.eps), irradiance, local_size=self.local_size)
