"""Impact Count (Arvo 1986): power landing on each triangle, over its area.

Each segment that ends on triangle t adds its power to t (fixed-point
atomics); E_t = sum / A_t. A vertex takes the mean of its triangles' values
and a point inside a triangle interpolates its three vertices linearly.
Cost O(n_R + n_V s + n_P). Its variance grows with the number of patches
(Shirley 1992): fine meshes need many photons.

Query points must lie on a triangle (camera and vertex points do; user
points are located on the surface within a small distance along their
normal, and an error names those that are not).
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.programs import launch, programs, read_buffer
from ..errors import OclgiError
from .base import Estimator


def vertex_triangles(faces: np.ndarray, n_vertices: int):
    """CSR lists of the triangles around each vertex: (starts, lists)."""
    flat = faces.ravel()
    order = np.argsort(flat, kind="stable")
    lists = (order // 3).astype(np.int32)
    counts = np.bincount(flat, minlength=n_vertices)
    starts = np.zeros(n_vertices + 1, np.int32)
    np.cumsum(counts, out=starts[1:])
    return starts, lists


class ImpactCount(Estimator):
    name = "impact"
    family = "impact"
    sums_per_point = False  # sums per triangle: a changed point only reads them

    def __init__(self, queue, compiled, points, radius=None, extension=None, **kw):
        # radius and extension are DETP parameters; Impact Count has none
        super().__init__(queue, compiled, points, **kw)
        prog = self.program("impact_count")
        self.k_acc, self.k_tri = prog.impact_count_accumulate, prog.impact_count_triangles
        self.k_vert, self.k_interp = prog.impact_count_vertices, prog.impact_count_interpolate
        scene = compiled.scene
        self.n_tris = scene.n_triangles
        self.n_vertices = len(scene.vertices)
        if points.kind != "camera" and (points.tri < 0).any():  # camera misses stay background
            points = locate(queue, compiled, points)
        self.points = points
        self.positions = self.upload(points.positions)
        self.barys = self.upload(points.barys)
        starts, lists = vertex_triangles(scene.faces, self.n_vertices)
        self.starts, self.lists = self.upload(starts), self.upload(lists)
        self.acc = self.zeros(self.n_tris * 3 * 8)
        self.tri_irr = self.zeros(self.n_tris * 16)
        self.vert_irr = self.zeros(self.n_vertices * 16)
        self.irr = self.zeros(self.n * 16)

    def replace_points(self, index: np.ndarray, new) -> None:
        # the interpolation reads faces[3 * tri]: a new point's id is checked as the first ones were
        new.check_triangles(self.n_tris, f"scene {self.compiled.scene.name!r}")
        if new.kind != "camera" and (new.tri < 0).any():
            new = locate(self.queue, self.compiled, new)
        self.points.positions[index] = new.positions
        self.points.normals[index] = new.normals
        self.points.barys[index] = new.barys
        cl.enqueue_copy(self.queue, self.positions, self.points.positions)
        cl.enqueue_copy(self.queue, self.barys, self.points.barys)

    def accumulate(self, batch):
        launch(self.queue, self.k_acc, batch.n_slots, batch.segments, batch.n_slots, batch.max_depth,
               self.count_emitted, self.acc, local_size=self.local_size)

    def resolve(self, scale: float) -> cl.Buffer:
        c = self.compiled
        launch(self.queue, self.k_tri, self.n_tris, self.acc, c.tri_areas, self.n_tris, 1.0 / scale, self.tri_irr)
        launch(self.queue, self.k_vert, self.n_vertices, self.tri_irr, self.starts, self.lists, self.n_vertices,
               self.vert_irr)
        launch(self.queue, self.k_interp, self.n, self.positions, self.barys, self.n, c.faces, self.vert_irr,
               self.irr)
        return self.irr

    def accumulators(self) -> np.ndarray:
        return read_buffer(self.queue, self.acc, (self.n_tris, 3), np.int64)


def locate(queue, compiled, points):
    """Find the triangle under each point (within 1e-4 of the scene diagonal)."""
    from ..queries import QueryPoints

    ctx = queue.context
    k = programs(ctx).get("bvh_query").bvh_query_locate
    mf = cl.mem_flags
    pos = points.positions.copy()
    pos_buf = cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=pos)
    nrm_buf = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=points.normals)
    bary = np.empty((len(points), 2), np.float32)
    bary_buf = cl.Buffer(ctx, mf.WRITE_ONLY, bary.nbytes)
    delta = 1e-4 * compiled.scene.diagonal
    launch(queue, k, len(points), *compiled.scene_args, pos_buf, nrm_buf, len(points), delta, bary_buf)
    cl.enqueue_copy(queue, pos, pos_buf)
    cl.enqueue_copy(queue, bary, bary_buf)
    tri = pos[:, 3].view(np.int32)
    if (tri < 0).any():
        bad = np.nonzero(tri < 0)[0]
        raise OclgiError(f"Impact Count needs points on a surface: {len(bad)} of {len(points)} points (first: "
                         f"{int(bad[0])}) are farther than {delta:.3g} from any triangle along their normal; use "
                         "method 'detp' for them")
    return QueryPoints(pos, points.normals, bary, points.kind, points.shape)
