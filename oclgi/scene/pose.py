"""Where the objects are: the state a move changes (ARCHITECTURE move M5).

A compiled scene (oclgi/scene/compiled.py) holds what never changes after
loading: the objects' trees, the triangles in tree order, materials,
textures, emitters. A ``Pose`` holds what a move changes: one ``Instance``
record per object (its world-from-object transform, the inverse and the
world box that culls it, kernels/bvh.h) on the host and on the device, and
the world normals of every triangle (the object normals through the
inverse transpose, kernels/instances.cl).

Every session owns a pose of its own (``Engine.posed``), so several
sessions over one engine, one compiled scene and one device can move
their objects independently: they share every tree and triangle, and each
pays only its instance records and a float4 normal per triangle.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..accel.boxes import box_corners
from ..cl.layout import Instance
from ..cl.programs import launch
from ..errors import OclgiError
from ..params import MAX_LENGTH
from .instance_boxes import instance_buffer, upload_instance


_AFFINE_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_AFFINE_TOL = 1e-8 + 1e-5 * _AFFINE_ROW


def as_transform(matrix) -> np.ndarray:
    """A validated affine 4x4 float64 matrix from a 4x4 or 3x4 one."""
    try:
        m = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        raise OclgiError(f"a transform must be a 4x4 or 3x4 array of numbers, got {matrix!r}") from None
    if m.shape == (3, 4):
        m = np.vstack([m, [0, 0, 0, 1]])
    # np.allclose's test on the last row, |a - b| <= 1e-8 + 1e-5 |b|, without its overhead (every move)
    if m.shape != (4, 4) or not np.isfinite(m).all() or not (np.abs(m[3] - _AFFINE_ROW) <= _AFFINE_TOL).all():
        raise OclgiError(f"a transform must be a finite affine 4x4 or 3x4 matrix, got shape {m.shape}")
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise OclgiError("the transform is singular (it flattens the object)")
    return m


def place_record(record, box, m: np.ndarray, name: str) -> None:
    """Set one Instance record (host) to transform ``m`` of an object whose
    box as loaded is ``box`` = (lo, hi); refused, the record untouched, when
    the object would leave float32's range."""
    lo, hi = box
    # From the transform as the record keeps it (float32): so placing an
    # object at the pose it reports (Pose.matrix) gives the same record,
    # its inverse and box included, bit for bit (a page's synced pose, a
    # checkpoint's).
    with np.errstate(over="ignore"):
        m = np.asarray(m, np.float64).astype(np.float32).astype(np.float64)
    world = box_corners(lo, hi) @ m[:3, :3].T + m[:3, 3]
    if not np.isfinite(world).all() or np.abs(world).max() > MAX_LENGTH:  # checked before any change
        raise OclgiError(f"the transform places object {name!r} beyond {MAX_LENGTH:.0e} of the origin, past what "
                         "the device's float32 coordinates hold")
    record["world_from_object"], record["object_from_world"] = m[:3], np.linalg.inv(m)[:3]
    # The world box only culls; pad it for float rounding of the transform.
    pad = 1e-6 * (np.abs(world).max() + np.abs(hi - lo).max())
    record["lo"], record["hi"] = world.min(axis=0) - pad, world.max(axis=0) + pad


class Pose:
    """The objects' instance records and the triangles' world normals, on
    the host (records) and the device (both), of one compiled scene.

    ``records``: the Instance array to start from (copied); ``normals``: the
    world normals, a host array (float4 per triangle) or a device buffer to
    copy on ``queue``."""

    def __init__(self, compiled, records: np.ndarray, normals, queue=None):
        self.compiled = compiled
        self.instances_host = np.array(records, dtype=Instance)
        mf = cl.mem_flags
        # the records, then their boxes in groups of 8 (oclgi/scene/instance_boxes.py)
        self.instances = instance_buffer(compiled.ctx, self.instances_host, mf.READ_WRITE)
        if isinstance(normals, cl.Buffer):
            self.tri_normals = cl.Buffer(compiled.ctx, mf.READ_WRITE, normals.size)
            cl.enqueue_copy(queue, self.tri_normals, normals, byte_count=normals.size)
        else:
            self.tri_normals = cl.Buffer(compiled.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR,
                                         hostbuf=np.ascontiguousarray(normals, np.float32))
        self.released = False
        self._uploads = ()  # the last move's record uploads (upload_instance)

    def copy(self, queue) -> "Pose":
        """An independent pose, equal to this one (the device normals copied, not recomputed)."""
        self._check()
        return Pose(self.compiled, self.instances_host, self.tri_normals, queue)

    def matrix(self, obj: int) -> np.ndarray:
        """Object ``obj``'s world-from-object transform (4x4 float64)."""
        m = np.eye(4)
        m[:3] = self.instances_host[obj]["world_from_object"]
        return m

    def place(self, queue, obj: int, matrix) -> None:
        """Move object ``obj``: ``matrix`` (4x4 or 3x4, world from the object
        as loaded) replaces its transform. Only its Instance record and the
        world normals of its triangles change; no tree is rebuilt."""
        self._check()
        m = as_transform(matrix)
        compiled = self.compiled
        obj_desc = compiled.scene.objects[obj]
        if not obj_desc.movable:
            raise OclgiError(f"object {obj_desc.name!r} is static")
        place_record(self.instances_host[obj], compiled.object_boxes[obj], m, obj_desc.name)
        self._uploads = upload_instance(queue, self.instances, self.instances_host, obj)  # kept: not waited for
        k = compiled.normals_kernel()
        launch(queue, k, int(self.instances_host[obj]["n_tris"]), compiled.object_normals, self.instances,
               obj, self.tri_normals)

    def release(self) -> set[int]:
        """Free the device buffers now (a closed session's pose); their ids."""
        if self.released:
            return set()
        self.instances.release()
        self.tri_normals.release()
        self.released = True
        return {id(self.instances), id(self.tri_normals)}

    def _check(self):
        if self.released:
            raise OclgiError("this pose was released (its session is closed)")
