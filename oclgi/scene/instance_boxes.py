"""The instances' world boxes as groups of 8 SoA lanes, after the records.

The top level of the scene's BVH is its instances (kernels/bvh.h): a ray
tests each instance's world box, in index order, and traverses the object
of each box it meets. One box at a time, the top level cost grew with the
number of objects: 10^6 rays in Sponza took 1.35x as long with 32 small
movable boxes, 2.1x with 64 (bench/HISTORY.md, "The top level with many
movable objects"). So the device
buffer holds, after the ``Instance`` records (from the next 32-byte
boundary), their boxes as
``InstanceBoxes`` groups (``oclgi.cl.layout``): instance 8 g + k in lane k
of group g, lanes past the last instance lo = hi = +inf. One float8 slab
test culls 8 instances; the ones it keeps are visited in index order and
tested again, one by one, with the box test a lone instance gets, so
every hit is the one the flat list gives, bit for bit.

A move changes one record and one group (``upload_instance``).
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..cl.constants import LANES
from ..cl.layout import Instance, InstanceBoxes


def box_groups(records: np.ndarray) -> np.ndarray:
    """The ``InstanceBoxes`` groups of the Instance ``records``."""
    n = len(records)
    groups = np.zeros((n + LANES - 1) // LANES, InstanceBoxes)
    for side in ("lo", "hi"):
        planes = np.full((len(groups) * LANES, 3), np.inf, np.float32)
        planes[:n] = records[side]
        for axis, name in enumerate("xyz"):
            groups[side + name] = planes[:, axis].reshape(-1, LANES)
    return groups


def groups_offset(n: int) -> int:
    """Where the groups start: the first 32-byte boundary (a float8's
    alignment) after ``n`` records (kernels/bvh.h computes the same)."""
    return (n * Instance.itemsize + 31) // 32 * 32


def instance_buffer_bytes(records: np.ndarray) -> np.ndarray:
    """What the device's instance buffer holds: the records, then their groups."""
    at, groups = groups_offset(len(records)), box_groups(records)
    out = np.zeros(at + groups.nbytes, np.uint8)
    out[:records.nbytes] = np.ascontiguousarray(records).view(np.uint8).ravel()
    out[at:] = groups.view(np.uint8)
    return out


def instance_buffer(ctx, records: np.ndarray, flags=cl.mem_flags.READ_ONLY) -> cl.Buffer:
    return cl.Buffer(ctx, flags | cl.mem_flags.COPY_HOST_PTR, hostbuf=instance_buffer_bytes(records))


def upload_instance(queue, buffer: cl.Buffer, records: np.ndarray, obj: int) -> tuple:
    """Bring record ``obj`` and its group up to date on the device, without
    waiting (a blocking copy costs a move 0.14 ms each): returns the copies'
    events, which hold their host arrays. Keep them until the copies are
    done: pyopencl waits for such an event when it is dropped."""
    item = records.dtype.itemsize
    g = obj // LANES
    group = box_groups(records[g * LANES:(g + 1) * LANES])
    return (cl.enqueue_copy(queue, buffer, records[obj:obj + 1].copy(), dst_offset=obj * item, is_blocking=False),
            cl.enqueue_copy(queue, buffer, group, dst_offset=groups_offset(len(records)) + g * InstanceBoxes.itemsize,
                            is_blocking=False))
