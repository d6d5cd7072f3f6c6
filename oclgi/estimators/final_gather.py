"""Final gathering for DETP (the option ``gather = N`` of every DETP
variant; the kernels are kernels/final_gather.cl).

Why. A DETP disc reads the mean irradiance over the disc from the
segments that cross it, so its error is the disc's: noise (a disc
catches few segments where the light is dim) and bias (the mean over the
disc is not the point's value near corners, edges and occluders). On a
scene lit mostly indirectly (the courtyard of bench/complex_scenes.py:
most points see no sun) both fall on the indirect light, which is
smooth over the hemisphere a point sees. Final gathering (Jensen's) moves
the density estimate one bounce away: from each query point x, N
cosine-distributed rays find the surfaces x sees, DETP estimates the
irradiance E(h) at those hits, and

    E(x) = E_direct(x) + (1 / N) sum_j rho(h_j) E(h_j)

(diffuse hits: their radiance towards x is rho E / pi, and cosine
sampling's pdf is cos / pi). The disc's bias and noise at the hits are
averaged over N different discs, and x's own disc, the one that straddles
x's corner or shadow edge, is gone.

What. ``gather = N`` (1 to 65536 rays per point; 0, the default: no
gathering) needs ``direct = "exact"``: the direct light of x and of each
hit comes by shadow rays and light samples, for every kind of light
(oclgi/estimators/detp_direct.py), the discs at the hits carry the
indirect light only (the photons' first segments do not count). Nothing
is counted twice: light from an emitter straight to x is x's direct
light, so a gather ray adds no emission at its first surface (an
emitting triangle it meets is a hit like any other, whose reflected
light its disc and direct light give); light from an emitter through a
mirror or glass to x is what no light sample sees, so a gather ray adds
the emission it meets past one (an emitting triangle's front, the sky it
leaves to). Light that bounced k times before x reaches it through the
hits' discs (k - 1 bounces before the hit, at most max_depth - 1), so a
gathered estimate holds up to max_depth bounces where the variant's own
holds max_depth - 1 (tests/test_final_gather.py checks both against the
furnace's series). The rays' random numbers are Philox
keyed by the run's seed, with ``gather_seed`` (default 0) in the counter: a
pure function of (seeds, point, ray, surface), so runs of different seeds
have independent rays (the study's variance is the gather's too). The discs at the hits are the variant's own (fixed or adaptive
radii, any DETP variant); their sums are its 64-bit fixed-point sums over
N discs per point; the gather's resolve adds each point's N rays in a
fixed order, one work-item per point, so the result is the same bits for
every work-group size and batch split.

The rays go through mirrors, glass and highlights as camera rays do
(kernels/camera.cl's rules) and stop at the first surface with a diffuse
part; the weight a hit is seen with includes its albedo (textures too).

Bias traded: the disc's, at the hits instead of at x (one bounce away,
where a disc's mean over its area changes E(x) little), plus the ray's
lift of eps off x. Variance: the hemisphere's (how much rho E varies over
what x sees) over N, plus the discs' noise averaged over N discs.

Cost: N rays per point at setup, N discs per point (a disc index of N n_P
discs: the segments' walk meets about N times more discs), and at each
resolve the direct light of N + 1 points per point (one shadow ray per
delta light; for the others 2 ``direct_samples`` rays at the point and 2
max(1, direct_samples // N) at each hit: the point's indirect light
averages its hits' noise).

Sessions over given points (oclgi/incremental/session.py) keep it exact
under moves: the hits' sums follow the changed photon paths as any query
point's do, and after each move ``regather`` traces every ray again (the
same pure function, at the new pose) and compares: a ray whose hit,
weight or seen emission changed gets its new disc, whose sums are taken
over the whole store, as a fresh run's would be. The rays are the same
for any point subset only by point index: a session keys them by each
point's index in its own static or dynamic set, so it equals a fresh
session at the same pose bit for bit (and a plain run when no point is on
a movable object). Light animations and light sessions (path reuse,
oclgi/tracing/light_reuse.py) keep it exact too: a light that moves moves
no geometry, so the rays and their hits stay; each frame's sums go to the
hits' discs (re-weighted, with disc indexing) and each frame's resolve
takes the direct light with the light where the frame has it. Camera
sessions too: their static layer's points stay for the camera (its rays
are traced again after each move, as given points' are) and the pixels
that see a movable object are new points each move, gathered afresh.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from .. import queries
from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError
from .base import Wrapping
from .detp_direct import DIRECT_SAMPLES, DirectLight, hit_samples
from .detp_direct import check as check_direct
from .gather_options import check


def gather_key(run_seed: int, gather_seed: int) -> tuple:
    """The rays' Philox key words (the run's seed, 64 bits) and counter
    block (gather_seed): every pair has its own rays."""
    return np.uint32(run_seed & 0xFFFFFFFF), np.uint32(run_seed >> 32), np.uint32(gather_seed)


def gather_rays(queue, compiled, pts: cl.Buffer, nrm: cl.Buffer, n_points: int, n_rays: int, key: tuple,
                local_size=None):
    """The hits of ``n_rays`` cosine rays from each of the ``n_points``
    points (device buffers of float4 positions and normals;
    kernels/final_gather.cl final_gather_rays) with Philox key ``key``
    (gather_key): (QueryPoints of the hits, point-major, their (n *
    n_rays, 4) float32 weights, and the emission each ray saw past a
    mirror or glass, times pi, on the device)."""
    ctx = queue.context
    n = n_points * n_rays
    mf = cl.mem_flags
    pos, hn, bary, wt = (cl.Buffer(ctx, mf.WRITE_ONLY, max(n, 1) * s) for s in (16, 16, 8, 16))
    emitted = cl.Buffer(ctx, mf.READ_WRITE, max(n, 1) * 16)  # the resolve reads it on the device
    c = compiled
    k = programs(ctx).get("final_gather").final_gather_rays
    launch(queue, k, n, *c.scene_args, c.tri_uvmap, c.tri_colourmap, c.tri_object, c.textures, c.texels,
           c.tri_normals, c.tri_material, c.materials, c.tri_emitter, c.spread_info, c.background,
           c.background_texels, pts, nrm, int(n_points), int(n_rays), *key, np.float32(c.eps), pos, hn, bary, wt,
           emitted, local_size=local_size)
    host = tuple(np.empty((n, k_), np.float32) for k_ in (4, 4, 2, 4))
    for h, dev in zip(host, (pos, hn, bary, wt)):
        cl.enqueue_copy(queue, h, dev)
    return queries.QueryPoints(*host[:3]), host[3], emitted


class FinalGather(Wrapping):
    """A DETP variant's discs at the hits of N rays per point, gathered back
    to the points (see the module's docstring)."""

    family = "detp"
    incremental = False  # not a session's method itself: a session's DETP variant gathers (regather)

    def __init__(self, variant, queue, compiled, points, radius: float, gather: int, gather_seed: int = 0,
                 direct: str = "photons", direct_samples: int = DIRECT_SAMPLES, direct_mis: str = "power",
                 seed: int = 0, point_direct: bool = True, **kw):
        n_rays = check(gather, gather_seed)
        if not check_direct(direct, direct_samples, direct_mis):
            raise OclgiError(f"gather (final gathering) needs direct = 'exact': the direct light of the points "
                             f"and of the hits by shadow rays, the discs the indirect light only (got direct = "
                             f"{direct!r})")
        count_work = kw.pop("count_work", False)
        super().__init__(queue, compiled, points, count_emitted=kw.get("count_emitted", True),
                         local_size=kw.get("local_size"), count_work=count_work)
        self.name = variant.name
        self.n_rays = n_rays
        # False: the points' own direct light is left out of the resolve
        # (an irradiance cache adds it at every pixel: irradiance_cache.py)
        self.point_direct = bool(point_direct)
        self.gather_seed = int(gather_seed)  # checked integral by check()
        # The direct light at the points themselves.
        self.direct = DirectLight(queue, compiled, self.count_emitted, self.local_size, direct_samples, direct_mis,
                                  seed)
        self.positions = self.upload(points.positions)
        self.normals = self.upload(points.normals)
        self.key = gather_key(int(seed), self.gather_seed)
        self.hits, self.hit_weights, self.emitted = gather_rays(queue, compiled, self.positions, self.normals,
                                                                self.n, n_rays, self.key, self.local_size)
        self.seen = None  # the emission the rays saw, on the host (read at the first regather)
        # The variant's own discs at the hits, with their own exact direct light.
        self.make_inner = lambda hits, radii=None: variant(
            queue, compiled, hits, radius, direct="exact", direct_samples=hit_samples(self.direct.samples, n_rays),
            direct_mis=direct_mis, seed=seed, count_work=count_work, **(kw if radii is None else dict(kw, radii=radii)))
        self.inner = self.make_inner(self.hits)
        self.radius = self.inner.radius
        self.weights_buf = self.upload(self.hit_weights)
        self.irr = self.zeros(self.n * 16)  # the points' irradiance, as every estimator's resolve leaves it
        self.k_resolve = self.program("final_gather").final_gather_resolve

    @property
    def radii(self) -> np.ndarray:
        """The discs' radii, one per hit (point-major, n_rays per point)."""
        return self.inner.radii

    @property
    def wrapped(self):
        """The hits' discs: the segments' sums are theirs."""
        return self.inner

    def set_direct_samples(self, samples: int) -> None:
        """The points' sample pairs from the next resolve on, the hits' their share."""
        self.direct.samples = int(samples)
        self.inner.set_direct_samples(hit_samples(samples, self.n_rays))

    def replace_points(self, index, new) -> None:
        raise OclgiError("gather (final gathering): the query points cannot be replaced (a session builds a "
                         "gathering estimator over its new points instead)")

    def regather(self, batch) -> int:
        """After a move: every ray traced again at the current pose; the
        rays whose hit (position, triangle, normal, barycentrics), weight or
        seen emission changed take their new disc, its sums over ``batch``
        (the whole store, as it is now). The number of rays changed."""
        hits, weights, emitted = gather_rays(self.queue, self.compiled, self.positions, self.normals, self.n,
                                             self.n_rays, self.key, self.local_size)
        n = self.n * self.n_rays
        seen_old = self.seen if self.seen is not None else read_buffer(self.queue, self.emitted, (n, 4), np.float32)
        seen_new = read_buffer(self.queue, emitted, (n, 4), np.float32)
        old = self.inner.points

        def bits(*arrays):
            return np.concatenate([np.ascontiguousarray(a, np.float32).reshape(n, -1).view(np.uint32)
                                   for a in arrays], axis=1)
        differ = bits(old.positions, old.normals, old.barys, self.hit_weights, seen_old) != bits(
            hits.positions, hits.normals, hits.barys, weights, seen_new)
        changed = np.nonzero(differ.any(axis=1))[0]
        self.emitted, self.seen = emitted, seen_new
        if not len(changed):
            return 0
        new = hits.subset(changed)
        self.inner.replace_points(changed, new)  # (adaptive radii: the new hits' radii, taken once here)
        fresh = self.make_inner(new, self.inner.radii[changed] if self.inner.adaptive is not None else None)
        # ^ the changed discs' sums over the whole store, as a fresh run's
        fresh.accumulate(batch)
        acc = self.inner.accumulators()
        acc[changed] = fresh.accumulators()
        cl.enqueue_copy(self.queue, self.inner.acc, acc)
        self.hit_weights = weights
        cl.enqueue_copy(self.queue, self.weights_buf, weights)
        return len(changed)

    def resolve(self, scale: float) -> cl.Buffer:
        """E(x) = the direct light at x + (1 / N) sum_j weight_j E(h_j)."""
        hit_irr = self.inner.resolve(scale)
        cl.enqueue_fill_buffer(self.queue, self.irr, np.float32(0), 0, self.n * 16)  # no host array a resolve
        if self.point_direct:
            self.direct.add(self.positions, self.normals, self.n, self.irr)
        launch(self.queue, self.k_resolve, self.n, hit_irr, self.weights_buf, self.emitted, self.n, self.n_rays,
               self.irr, local_size=self.local_size)
        return self.irr
