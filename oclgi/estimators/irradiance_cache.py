"""Irradiance caching for renders: final gathering at a sparse grid of the
image's points, the indirect light interpolated to the others (the option
``gather_spacing = s`` of a DETP render with ``gather = N`` and
``direct = "exact"``; the kernels are kernels/irradiance_cache.cl).

Why. Final gathering (oclgi/estimators/final_gather.py) makes the indirect
light smooth and unbiased by any disc at the point itself, but N rays a
pixel and N discs a ray cost far more than an image needs: the indirect
light varies slowly across a surface (Ward's observation behind irradiance
caching, 1988), while what varies from pixel to pixel, the edges of the
geometry, the textures and the direct light's shadows, needs each pixel's
own samples. So the direct light stays exact at every point (every sample
of every pixel), and the indirect light is gathered at one pixel in s x s
and interpolated. On the Cornell box at 128 x 128 (bench/README.md,
"Images at equal error") 16 samples a pixel gathered at one pixel in 3 x 3
with 128 rays reach Mitsuba 3's error at 256 spp in 0.40x its time, where
the photons' own estimate at 16 samples takes 6.5x, and gathering at every
point would cost 9 x 16 times the rays.

What. The records are sample 0's points at every s-th pixel each way
(pixel (s gx, s gy)), and every point no such record can stand for: the
interpolation's weights (kernels/irradiance_cache.cl: a tent over two
grid cells in the image, the normals' agreement to the 16th power, the
offset's angle off the record's plane against about 6 degrees, records of
the point's own material only) are functions of the geometry alone, computed before anything is
gathered, and a point whose weights sum to less than ``MIN_WEIGHT`` (an
edge's far side, a thin part, a corner's other wall) is gathered itself.
Each record's indirect irradiance is the gather's (N rays, the variant's
discs at their hits, nothing counted twice: final_gather.py); a point's
is its own record's, or the weighted mean of the 4 x 4 grid records
around its pixel; its direct light is then added by shadow rays
(oclgi/estimators/detp_direct.py) with ``direct_samples`` pairs per point.

Exact as the rest: the records, their rays and their discs are a pure
function of the points and the seeds; each point's mean reads its 16
records in a fixed order (one work-item a point), so the image is the
same bits for every work-group size and batch split (the sums
are the discs' 64-bit fixed-point ones). A render resumed from a
checkpoint continues the same sums.

Bias traded: the interpolation's, where the indirect light bends within
two grid cells (a corner's darkening, a contact shadow): bounded by
gathering wherever the geometry differs, not by the light. Against final
gathering at every point (tests/test_irradiance_cache.py) the images'
total light agrees within 0.2-1.3% on the Cornell box, CornellBox-Sphere
and the glossy box at 64 x 64 with a spacing of 3. A caustic seen only
through the gather rays (light through glass onto a diffuse floor) is the
records' where they sit in it, and lost between them: narrower than the
spacing, it is gone (CornellBox-Sphere's, at 32 x 32 with a spacing of 4:
5.7% of the image's light). Caustics want photons at the point itself
(``method="photon_map"``, or the disc estimate without gathering). With s = 1 it
is final gathering at every point (``gather_spacing`` 1, the default).
Renders only: a session's points change with every move, and it gathers
at each of them.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from .. import budget
from ..cl.programs import launch, read_buffer
from ..errors import OclgiError
from .base import Wrapping
from .detp_direct import DIRECT_SAMPLES
from .gather_options import spacing as check_spacing

# A point whose records' weights sum to less than this (one record of the
# same plane and facing, two cells off in one axis: 0.5) is gathered itself.
MIN_WEIGHT = 1e-3


class IrradianceCache(Wrapping):
    """Final gathering at a grid of a render's points and where the grid
    cannot stand for a point, interpolated to the rest (module docstring)."""

    family = "detp"
    incremental = False

    def __init__(self, variant, queue, compiled, points, radius: float, gather: int, gather_spacing: int = 1,
                 direct: str = "photons", direct_samples: int = DIRECT_SAMPLES, direct_mis: str = "power",
                 seed: int = 0, **kw):
        from .final_gather import FinalGather

        spacing = check_spacing(gather_spacing)
        if points.kind != "camera" or points.shape is None:
            raise OclgiError("gather_spacing interpolates over an image: it takes a render's points (Engine.render, "
                             "oclgi render); a session or given points gather at every point")
        count_work = kw.pop("count_work", False)
        super().__init__(queue, compiled, points, count_emitted=kw.get("count_emitted", True),
                         local_size=kw.get("local_size"), count_work=count_work)
        self.name = variant.name
        rows, width = points.shape
        height = rows // points.samples
        self.spacing, self.width, self.height = spacing, width, height
        gh, gw = -(-height // spacing), -(-width // spacing)
        gy, gx = np.mgrid[0:gh, 0:gw]
        grid = (gy * spacing * width + gx * spacing).ravel()
        sees = points.tri[grid] >= 0
        cells = np.full(gh * gw, -1, np.int32)
        cells[sees] = np.arange(int(sees.sum()), dtype=np.int32)
        self.grid_records = grid[sees]
        self.positions = self.upload(points.positions)
        self.normals = self.upload(points.normals)
        prog = self.program("irradiance_cache")
        self.k_interpolate = prog.irradiance_cache_interpolate
        self.geometry = (np.int32(width), np.int32(height), np.int32(spacing), np.int32(gw), np.int32(gh),
                         self.upload(cells), self.upload(points.positions[self.grid_records]),
                         self.upload(points.normals[self.grid_records]), compiled.tri_material)
        self.irr = self.zeros(self.n * 16)  # the weights' pass first, then each resolve's irradiance
        alone = np.nonzero((self._weights() < MIN_WEIGHT) & (points.tri >= 0))[0]
        own = np.full(self.n, -1, np.int32)
        own[alone] = len(self.grid_records) + np.arange(len(alone), dtype=np.int32)
        self.own = self.upload(own)
        self.records = np.concatenate([self.grid_records, alone])
        device, host = budget.gather_buffers(self.name, len(self.records), gather)
        budget.check(budget.Need(f"final gathering at {len(self.records):,} of the image's points with {gather:,} "
                                 f"rays each", device, host, "use fewer gather rays, a larger gather_spacing or "
                                 "a smaller width/height"), queue.device)
        # The records gather the indirect alone; the gather's direct light
        # (its points' own, left out there) serves every point here.
        self.gather = FinalGather(variant, queue, compiled, points.subset(self.records), radius, gather,
                                  direct=direct, direct_samples=direct_samples, direct_mis=direct_mis, seed=seed,
                                  point_direct=False, count_work=count_work, **kw)
        self.direct = self.gather.direct
        self.radius = self.gather.radius

    def _weights(self) -> np.ndarray:
        """Each point's sum of weights (the geometry's alone), through ``irr``."""
        unread = self.zeros(16)  # ``own`` and the records' irradiance, not read by the weights' pass
        launch(self.queue, self.k_interpolate, self.n, self.positions, self.normals, np.int32(self.n),
               *self.geometry, np.int32(1), unread, unread, self.irr, local_size=self.local_size)
        return read_buffer(self.queue, self.irr, (self.n, 4), np.float32)[:, 0]

    @property
    def wrapped(self):
        return self.gather

    @property
    def n_records(self) -> int:
        """The points gathered at: the grid's and those it cannot stand for."""
        return len(self.records)

    def set_direct_samples(self, samples: int) -> None:
        self.gather.set_direct_samples(samples)  # its direct light is this one's too

    def replace_points(self, index, new) -> None:
        raise OclgiError("gather_spacing: a render's points cannot be replaced (a session gathers at every point)")

    def resolve(self, scale: float) -> cl.Buffer:
        """E(x) = the direct light at x + the records' indirect light at x."""
        indirect = self.gather.resolve(scale)
        launch(self.queue, self.k_interpolate, self.n, self.positions, self.normals, np.int32(self.n),
               *self.geometry, np.int32(0), self.own, indirect, self.irr, local_size=self.local_size)
        self.direct.add(self.positions, self.normals, self.n, self.irr)
        return self.irr
