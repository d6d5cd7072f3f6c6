"""Shading normals: a mesh's own vertex normals (OBJ ``vn``, glTF and PLY
normals), interpolated over each triangle, packed for the device
(``kernels/shading_normals.h`` evaluates them).

Where they are used, and why only there: the query points a camera makes
(kernels/camera.cl) take the shading normal as their normal, so the discs
(DETP) and neighbourhoods (Photon Maps, Ray Maps) of a curved surface turn
with it and its image shades smoothly, and the render's normal layer shows
it. Photon tracing keeps the geometric normals for its cosines and side
tests: a photon scattered about a shading normal needs Veach's adjoint
correction |wo.ns||wi.ng| / (|wo.ng||wi.ns|) to conserve energy, a factor
with no bound at grazing angles, which would break the bound on a photon's
weight (<= 1) that the fixed-point sums' overflow argument rests on
(kernels/oclgi_types.h); and a side test against a normal that is not the
triangle's would let light through it. So photons, and the sums of every
estimator, see the same geometry as before; only where the image looks at
it does the surface become smooth.

A disc turned by the angle a between the shading and the geometric normal
has half of itself behind its triangle's plane, where no segment reaches
(the segments end on the triangle): it would lose up to half the light. The
camera therefore lifts the disc's centre off the triangle along the
geometric normal by d sin a (d the disc radius), the least that keeps the
whole disc in front of the plane; on a convex mesh (every other triangle
behind that plane) the whole disc is then outside the mesh and every
segment through it is counted, so the estimate is the flux through the
turned disc: the irradiance of the smooth surface the normals describe.

Like texture coordinates (oclgi/scene/textures.py), the normal at a point
comes from the point itself through each triangle's affine map from its
plane to the interpolated normal, in object space (moved objects: through
their instance's transform in the kernel), so no barycentrics are needed.
A triangle without a full set of corner normals, or with one further than
60 degrees from its own normal (oclgi/scene/scene.py MAX_SHADING_ANGLE: a
hard edge the file averaged over), has an all-zero map: the kernel then
takes the geometric normal, bit for bit what it took before.
"""

from __future__ import annotations

import numpy as np

from .textures import affine_maps


def normal_maps(tri_vertices: np.ndarray, tri_normals: np.ndarray | None) -> np.ndarray:
    """(3 F, 4) float32: per triangle three float4 rows, the affine maps
    (m, c) to the interpolated normal's x, y and z (oclgi.scene.textures
    affine_maps), zero for a triangle without vertex normals (NaN corners)
    and for every triangle when ``tri_normals`` is None."""
    n = len(tri_vertices)
    if tri_normals is None:
        return np.zeros((3 * n, 4), np.float32)
    smooth = np.isfinite(tri_normals).all(axis=(1, 2))
    maps = affine_maps(tri_vertices, np.where(smooth[:, None, None], tri_normals, 0.0))
    maps[~smooth] = 0.0
    return maps.reshape(3 * n, 4).astype(np.float32)
