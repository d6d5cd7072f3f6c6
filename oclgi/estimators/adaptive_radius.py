"""Adaptive DETP radii (``radius_mode="adaptive"`` of plain DETP and disc
indexing): one disc radius per query point, from the local ray density and
capped by the local geometry, fixed when the estimator is built.

One global radius d is a compromise (issue 16): wide discs read the mean of
a neighbourhood that bright spots, corners, small surfaces and occluders
spoil; narrow ones are noisy where the light is dim. Per point i:

1. Density. A *pilot* of ``pilot_photons`` paths (its own seed,
   ``PILOT_SEED``, so the radii depend on neither the run's seed nor its
   batches) is traced, and Ray Maps' k-nearest search
   (:class:`oclgi.estimators.ray_map_knn.SegmentKnnIndex`, the plane
   metric: the tangent-plane crossings DETP counts) gives r_k(i), the
   distance to the ``adaptive_k``-th nearest crossing. For a uniform
   density of the pilot's N segments over the scene's area A that distance
   is r_u = sqrt(k A / (pi N)); the density radius is

       r_dens(i) = d * clip(r_k(i) / r_u, radius_min, 1)

   so a disc holds about as many segments as the fixed disc does at the
   scene's mean density: where the light is concentrated (near a light, in
   a caustic) the disc shrinks with the density and the relative noise
   stays that of the fixed disc, with less blur. It never grows past d:
   growing in the dark is what makes shadowed points read the light beside
   them (issue 16).
2. Geometry (oclgi/estimators/surface_patches.py). The disc is capped by
   the distance b(i) from the point to the boundary of its smooth surface
   patch, floored by min(radius_min d, half the radius of the patch's
   area) so that points on a patch's edge keep a disc (a point on a
   wall's seam still gets radius_min d; a point on a leaf smaller than
   that gets about a quarter of the leaf's side):

       r(i) = min(r_dens(i), max(b(i), min(radius_min d, s(i))))

Why this floor: on the generated foliage (bench/complex_accuracy.py, 10^7
photons, 256 points) floors of a half and a quarter of s(i) left as many
or more points off by 2x (8 and 10, against 8 at s(i)) for the same median
(1.57% and 1.55%, against 1.59%): below s(i) the noise of the small disc
costs as much as the rays passing beside the leaf that a disc overhanging
its edge still counts (what surface-consistent counting would remove).

The radii are a pure function of each point (its position, normal and
triangle), the pilot (traced at the scene's pose when the estimator is
built) and the patches (of the triangles as loaded): the same
for any batch split, work-group size or subset of points, which is what
makes the session's exact update hold (oclgi/incremental/session.py builds
the estimator once; its radii stay those of the first frame).

Cost: the pilot trace, the pilot's k-nearest index (host build, about 1 s
for 10^5 segments) and one search per point, and the patches (host numpy,
once) and each point's distance to its patch's boundary (on the device).

Parameters (options of ``detp`` and ``detp_disc_index``):

=================  ========  =================================================
option             default   meaning
=================  ========  =================================================
``radius_mode``    "fixed"   "fixed": the run's radius d everywhere (as
                             before, bit for bit); "adaptive": the radii above
``adaptive_k``     16        neighbours of the pilot's search, 2..256
``pilot_photons``  32768     paths of the pilot, 1,024..4,194,304
``radius_min``     0.25      smallest density radius, and the geometric
                             floor, as a fraction of d, in (0, 1]
``radii``          None      with "adaptive": each point's radius, given
                             instead of computed (a session's first frame's,
                             to recompute with the radii it keeps)
=================  ========  =================================================

The options are checked by oclgi/estimators/radius_options.py.
"""

from __future__ import annotations

import math

import numpy as np

from .ray_map_knn import SegmentKnnIndex
from .surface_patches import SurfacePatches

# The pilot's paths, traced by the engine (Engine.estimator): their own seed,
# not any run's, so the radii do not change with the run's seed.
PILOT_SEED = 0x5EED_AD47
PILOT_MAX_DEPTH = 16


class AdaptiveRadii:
    """The pilot's index and the scene's patches, kept to give the radii of
    any points of the scene (``radii``).

    ==============  =============================================================
    parameter       meaning
    ==============  =============================================================
    queue           the OpenCL queue
    compiled        the compiled scene (its scene's geometry, area and eps)
    pilot           the pilot's paths (a PathBatch of ``pilot_photons`` paths
                    from PILOT_SEED, traced by Engine.estimator)
    radius          d, the run's radius
    extension       e, the user's extension (as DETP's)
    count_emitted   whether segments leaving the lights count (as DETP's)
    adaptive_k      k of the pilot's search
    radius_min      smallest radius, as a fraction of d
    local_size      the work-group size (no result depends on it)
    ==============  =============================================================
    """

    def __init__(self, queue, compiled, pilot, radius: float, extension: float, count_emitted: bool,
                 adaptive_k: int = 16, radius_min: float = 0.25, local_size: int | None = None):
        self.queue, self.radius, self.k = queue, float(radius), int(adaptive_k)
        self.radius_min, self.local_size = float(radius_min), local_size
        scene = compiled.scene
        segs = pilot.read_segments(queue)
        keep = (segs["dir"] != 0).any(axis=1)  # empty slots and holes have no direction
        if not count_emitted:
            keep[::pilot.max_depth] = False
        s = segs[keep]
        self.index = None
        self.r_u = math.inf
        area = float(np.sum(compiled.areas, dtype=np.float64))
        if len(s) >= self.k and area > 0:
            ext = np.float32(float(extension) + 10.0 * compiled.eps)
            lo, hi = scene.bounds()
            self.index = SegmentKnnIndex(queue, s["org"], s["dir"], s["t_end"] + ext, s["power"],
                                         np.asarray(lo, np.float64), np.asarray(hi, np.float64), "plane")
            self.r_u = math.sqrt(self.k * area / (math.pi * len(s)))
        self.patches = SurfacePatches(scene.vertices, scene.faces)

    def radii(self, points) -> np.ndarray:
        """(n,) float64 radius of each of ``points`` (QueryPoints)."""
        d = self.radius
        n = len(points)
        ratio = np.ones(n)
        if self.index is not None and n:
            _, d2, _, _ = self.index.neighbours(points.positions, points.normals, self.k,
                                                local_size=self.local_size)
            ratio = np.sqrt(d2[:, -1].astype(np.float64)) / self.r_u  # inf: fewer than k found
        r_dens = d * np.clip(ratio, self.radius_min, 1.0)
        tri = points.tri
        cap = np.maximum(self.patches.boundary_distance(self.queue, points.positions, tri, self.local_size),
                         np.minimum(self.radius_min * d, self.patches.patch_size(tri)))
        return np.minimum(r_dens, cap)
