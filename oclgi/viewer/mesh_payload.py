"""What every page loads once: the tessellated scene's mesh and a description.

The mesh is the tessellation's vertices as loaded (float32), its faces, and
the object each vertex belongs to (0 for a static vertex, 1 + i for the
i-th movable object): the page moves a movable object's vertices by the
object's current pose relative to its loaded one, so a move sends no
geometry. Layout, little-endian:

    b"OGVM", uint32 vertices V, uint32 faces F, uint32 0,
    float32 position[V][3], uint32 object[V], uint32 face[F][3]
"""

from __future__ import annotations

import struct

import numpy as np

MAGIC = b"OGVM"


def vertex_objects(scene, vertex_tri: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """(per vertex 0 or 1 + its movable object's rank, the movable objects' ids)."""
    ranges = scene.object_ranges()
    movable = [i for i, o in enumerate(scene.objects) if o.movable]
    out = np.zeros(len(vertex_tri), np.uint32)
    for rank, obj in enumerate(movable):
        a, b = ranges[obj]
        out[(vertex_tri >= a) & (vertex_tri < b)] = rank + 1
    return out, movable


def mesh_bytes(tess, objects: np.ndarray) -> bytes:
    v = np.ascontiguousarray(tess.vertices, "<f4")
    f = np.ascontiguousarray(tess.faces, "<u4")
    return (struct.pack("<4sIII", MAGIC, len(v), len(f), 0) + v.tobytes()
            + np.ascontiguousarray(objects, "<u4").tobytes() + f.tobytes())


def description(engine, tess, movable: list[int]) -> dict:
    """The scene as the page needs it: camera, bounds, movable objects and
    their loaded matrices (row-major), the mesh's size."""
    scene = engine.scene
    cam = scene.camera
    lo, hi = scene.bounds()
    objects = []
    for obj in movable:
        name = scene.objects[obj].name
        objects.append({"name": name, "matrix": engine.pose_matrix(name).reshape(-1).tolist()})
    return {
        "name": scene.name,
        "vertices": int(len(tess.vertices)),
        "faces": int(len(tess.faces)),
        "edge": float(tess.edge),
        "bounds": [list(map(float, lo)), list(map(float, hi))],
        "diagonal": float(scene.diagonal),
        "camera": None if cam is None else {"position": list(map(float, cam.position)),
                                            "look_at": list(map(float, cam.look_at)),
                                            "up": list(map(float, cam.up)), "fov": float(cam.fov)},
        "objects": objects,
    }
