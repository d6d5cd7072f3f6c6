"""Smooth surface patches of a mesh and the distance from a point to its
patch's boundary: the geometric cap of adaptive DETP radii
(oclgi/estimators/adaptive_radius.py).

A DETP disc estimates the mean irradiance over the disc, on the plane
tangent at the point (DESIGN.md 3). Where the surface the point lies on
ends within the disc (a leaf smaller than the disc, a wall meeting the
floor, a column's edge), part of the disc lies off the surface: it counts
rays that pass beside the surface, or misses the light the surface gets.
The disc is only as good as the patch of surface that supports it, so the
cap is the distance from the point to the boundary of its *patch*:

    patch     triangles joined across shared edges whose normals differ by
              less than ``SMOOTH_COS`` (25 degrees): a flat wall, a leaf
              quad, a finely tessellated curved surface, but not a box's
              faces (90 degrees) nor a wall and the floor it meets.
    boundary  the edges of a patch's triangles that join no other triangle
              of the patch (the mesh's border, a crease, a seam between two
              meshes: vertices are welded by their exact coordinates).

Why the boundary distance and not the triangle's size: a big wall made of
two long triangles would cap every point by its triangle, and a finely
tessellated plane would cap the radius to the tessellation; the patch
follows the surface, not the mesh.

Cost: the patches, O(F log F) on the host; the distances, every point
against every boundary edge of its own patch, O(points x edges per patch),
one work-item per point on the device (kernels/surface_patches.cl).
"""

from __future__ import annotations

import numpy as np

from ..scene.scene import triangle_areas

SMOOTH_COS = float(np.cos(np.radians(25.0)))  # neighbours closer than 25 degrees are one patch


def triangle_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    v = vertices[faces]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length > 0, length, 1.0)


class SurfacePatches:
    """The patches of a triangle mesh (``vertices`` (V, 3), ``faces`` (F, 3)).

    Attributes: ``label`` (F,) the patch of each triangle; ``area`` the area
    of each patch; ``edges`` (E, 2, 3) the boundary edges and ``edge_patch``
    (E,) their patches, sorted by patch with ``offsets`` (patches + 1,)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, smooth_cos: float = SMOOTH_COS):
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        vertices = np.asarray(vertices, np.float64)
        faces = np.asarray(faces, np.int64)
        nf = len(faces)
        # weld vertices by exact position: meshes repeat a vertex per face or material
        _, weld = np.unique(vertices, axis=0, return_inverse=True)
        f = weld.reshape(-1)[faces]
        a = f[:, [0, 1, 2]].reshape(-1)
        b = f[:, [1, 2, 0]].reshape(-1)
        key = np.minimum(a, b) * (int(weld.max()) + 1) + np.maximum(a, b)
        tri = np.repeat(np.arange(nf), 3)
        order = np.argsort(key, kind="stable")
        ks, ts = key[order], tri[order]
        # an edge shared by exactly two triangles joins them when they are nearly coplanar
        same_next = ks[1:] == ks[:-1]
        single = np.ones(len(ks), bool)
        pair = np.nonzero(same_next)[0]
        # edges of more than two triangles (non-manifold) join nothing
        triple = np.zeros(len(ks), bool)
        triple[1:-1] = same_next[1:] & same_next[:-1]
        bad = np.zeros(len(ks), bool)
        for shift in (0, 1, 2):
            idx = np.nonzero(triple)[0] - 1 + shift
            bad[idx[(idx >= 0) & (idx < len(ks))]] = True
        pair = pair[~bad[pair] & ~bad[pair + 1]]
        nrm = triangle_normals(vertices, faces)
        t0, t1 = ts[pair], ts[pair + 1]
        joined = np.einsum("ij,ij->i", nrm[t0], nrm[t1]) >= smooth_cos
        pair = pair[joined]
        single[pair] = False
        single[pair + 1] = False
        graph = coo_matrix((np.ones(len(pair)), (ts[pair], ts[pair + 1])), shape=(nf, nf))
        self.n_patches, self.label = connected_components(graph, directed=False)
        v = vertices[faces]
        self.area = np.bincount(self.label, weights=triangle_areas(vertices, faces), minlength=self.n_patches)
        # boundary: the edge occurrences that joined nothing
        occ = order[single]  # index into the (F * 3) edge occurrences
        t, k = occ // 3, occ % 3
        ends = np.stack([v[t, k], v[t, (k + 1) % 3]], axis=1)
        patch = self.label[t]
        by = np.argsort(patch, kind="stable")
        self.edges, self.edge_patch = ends[by], patch[by]
        self.offsets = np.searchsorted(self.edge_patch, np.arange(self.n_patches + 1))
        self._device = None  # (context, label, offsets, edges) buffers, made by boundary_distance

    def boundary_distance(self, queue, positions: np.ndarray, tri: np.ndarray, local_size=None) -> np.ndarray:
        """Distance from each point (``positions`` (n, 3 or 4) on triangle
        ``tri``) to the boundary of its patch, on the device
        (kernels/surface_patches.cl, float32): inf for a closed patch (a
        sphere) or a point on no triangle (tri < 0)."""
        import pyopencl as cl

        from ..cl.programs import launch, programs, read_buffer

        n = len(positions)
        if n == 0:
            return np.zeros(0)
        ctx = queue.context
        mf = cl.mem_flags
        if self._device is None or self._device[0] is not ctx:  # the patches' tables, uploaded once per context
            ends = np.zeros((max(len(self.edges), 1), 2, 4), np.float32)
            ends[:len(self.edges), :, :3] = self.edges
            tables = (self.label.astype(np.int32), self.offsets.astype(np.int32), ends)
            self._device = (ctx, *(cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(t))
                                   for t in tables))
        _, label, offsets, edges = self._device
        pos = np.zeros((n, 4), np.float32)
        pos[:, :3] = np.asarray(positions)[:, :3]
        pos_buf = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=pos)
        tri_buf = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(tri, np.int32))
        out_buf = cl.Buffer(ctx, mf.WRITE_ONLY, n * 4)
        launch(queue, programs(ctx).get("surface_patches").patch_boundary_distance, n, pos_buf, tri_buf, label,
               offsets, edges, n, out_buf, local_size=local_size)
        return read_buffer(queue, out_buf, n, np.float32).astype(np.float64)

    def patch_size(self, tri: np.ndarray) -> np.ndarray:
        """Half the radius of the disc with the area of each point's patch:
        a floor of the cap that is still well inside a small patch (a leaf
        quad of side s gives 0.28 s); inf for points on no triangle."""
        tri = np.asarray(tri, np.int64)
        out = np.full(len(tri), np.inf)
        on = tri >= 0
        out[on] = 0.5 * np.sqrt(self.area[self.label[tri[on]]] / np.pi)
        return out
