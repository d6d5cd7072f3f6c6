"""Coarser copies of the tessellation for the page to draw while the view moves.

A software-rendered browser (SwiftShader, 2 cores) draws about two
triangles a microsecond: the Cornell box + bunny's 100k faces take 70 ms a
frame, Sponza's 556k 300 ms. While the camera or an object moves the page
draws a level of detail instead, and the full tessellation again once the
view rests (oclgi/viewer/static/viewer.js chooses by its measured frame
time, so a browser that draws the full mesh in time keeps it). The levels
are made here once, when the server starts, by vertex clustering
(Rossignac and Borrel, 1993):

- a vertex's cluster is its (object, grid cell, normal's direction): the
  object (static, or a movable object's rank) so that a movable object's
  clusters move with it; the cell of a cubic grid of side ``h`` over the
  positions as loaded (the mesh's own); the direction the largest
  component of its normal points along (one of six), so that a wall and the
  floor at a corner, or a thin wall's two sides, stay apart;
- a cluster's position is the plain mean of its vertices' positions;
- a cluster's colour is the area-weighted mean of its vertices' exact
  colours: ``c = sum(a_v c_v) / sum(a_v)`` per channel, in float64, rounded
  to float32, ``a_v`` a third of the area of the faces at vertex v (its
  share of the surface); a cluster whose vertices' faces have no area
  takes the plain mean;
- a face of the level is a face of the tessellation with each corner
  replaced by its cluster: dropped when two corners share a cluster, kept
  once per set of three clusters (the first such face's orientation);
  clusters that no face of the level uses are dropped;
- ``h`` is chosen so that the level has about the number of faces asked
  for (a few steps of h *= sqrt(faces / target) from the grid whose cells
  hold the target's share of the surface).

The colours of a level are thus a fixed linear function of the exact
colours (one sparse averaging matrix, built here), deterministic and
computed from the exact colours the server already has: the level's frame
is a function of the full one, never a separate estimate.

The page loads the levels once (``/levels.bin``, ``levels_bytes``), little-endian:

    b"OGVL", uint32 L, then per level k = 1..L (finest first):
    uint32 C, uint32 G, float32 h, uint32 0,
    float32 position[C][3], uint32 object[C], uint32 face[G][3]
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

FACES_STEP = 4  # each level has about a quarter of the faces of the one before
MIN_FACES = 6_000  # the coarsest level: about 3 ms a frame in software (SwiftShader on 2 cores)
TOLERANCE = 0.15  # a level's faces within 15% of its target
MAX_STEPS = 8


@dataclass(frozen=True)
class Level:
    """One level of detail: its mesh and the averaging that gives its colours."""

    cell: float  # the grid's side h
    positions: np.ndarray  # (C, 3) float32, the clusters' mean positions (as loaded)
    objects: np.ndarray  # (C,) uint32: 0 static, 1 + rank of a movable object
    faces: np.ndarray  # (G, 3) uint32 into positions
    average: object  # scipy.sparse CSR (C, V): row c is a_v over the cluster's vertices
    weight: np.ndarray  # (C,) float64: each row's sum (the plain count for an area-less cluster)

    def colours(self, exact: np.ndarray) -> np.ndarray:
        """(C, 3) float32: each cluster's area-weighted mean of ``exact`` (V, 3), the module's rule."""
        total = self.average @ np.asarray(exact, np.float64)
        return (total / self.weight[:, None]).astype(np.float32)


def vertex_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V,) float64: a third of the area of the faces at each vertex."""
    from ..scene.scene import triangle_areas

    area = triangle_areas(np.asarray(vertices, np.float64), faces)
    return np.bincount(faces.reshape(-1), np.repeat(area / 3.0, 3), minlength=len(vertices))


def _clusters(vertices, normals, objects, cell: float) -> np.ndarray:
    """(V,) int64: each vertex's cluster, numbered in the order of their keys."""
    lo = vertices.min(axis=0)
    ijk = np.floor((vertices - lo) / cell).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    axis = np.argmax(np.abs(normals), axis=1)
    direction = 2 * axis + (normals[np.arange(len(normals)), axis] < 0)
    key = (((objects.astype(np.int64) * 6 + direction) * dims[0] + ijk[:, 0]) * dims[1] + ijk[:, 1]) * dims[2] \
        + ijk[:, 2]
    return np.unique(key, return_inverse=True)[1].reshape(-1)


def _faces(cluster: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The level's faces (G, 3) int64 in clusters: degenerate ones dropped, one per set of three clusters."""
    cf = cluster[faces]
    cf = cf[(cf[:, 0] != cf[:, 1]) & (cf[:, 1] != cf[:, 2]) & (cf[:, 0] != cf[:, 2])]
    s = np.sort(cf, axis=1)
    n = int(cluster.max()) + 1
    key = (s[:, 0] * n + s[:, 1]) * n + s[:, 2] if n < 2 ** 21 else None
    if key is None:
        _, first = np.unique(s, axis=0, return_index=True)
    else:
        _, first = np.unique(key, return_index=True)
    return cf[np.sort(first)]


def make_level(vertices, normals, faces, objects, area, cell: float) -> Level:
    """The level of grid side ``cell`` (the module's rule)."""
    from scipy.sparse import csr_matrix

    vertices = np.asarray(vertices, np.float64)
    cluster = _clusters(vertices, normals, objects, cell)
    level_faces = _faces(cluster, faces)
    used = np.unique(level_faces)  # the clusters a face uses, renumbered in order
    renumber = np.full(int(cluster.max()) + 1, -1, np.int64)
    renumber[used] = np.arange(len(used))
    c = renumber[cluster]  # -1: a vertex whose cluster the level does not draw
    inside = np.nonzero(c >= 0)[0]
    C = len(used)
    count = np.bincount(c[inside], minlength=C).astype(np.float64)
    a_sum = np.bincount(c[inside], area[inside], minlength=C)
    flat = a_sum <= 0  # no area: the plain mean
    w = np.where(flat[c[inside]], 1.0, area[inside])
    average = csr_matrix((w, (c[inside], inside)), shape=(C, len(vertices)))
    average.sum_duplicates()
    positions = np.zeros((C, 3))
    for k in range(3):
        positions[:, k] = np.bincount(c[inside], vertices[inside, k], minlength=C)
    positions /= count[:, None]
    obj = np.zeros(C, np.uint32)
    obj[c[inside]] = objects[inside]
    return Level(float(cell), positions.astype(np.float32), obj, renumber[level_faces].astype(np.uint32),
                 average, np.where(flat, count, a_sum))


def level_for(vertices, normals, faces, objects, area, target: int) -> Level:
    """A level of about ``target`` faces (within TOLERANCE, or the closest of MAX_STEPS tries)."""
    total = float(area.sum())
    cell = np.sqrt(2.0 * total / max(target, 1))  # half a cell's square a face: the target's share of surface
    best = None
    for _ in range(MAX_STEPS):
        level = make_level(vertices, normals, faces, objects, area, cell)
        g = len(level.faces)
        if best is None or abs(np.log(max(g, 1) / target)) < abs(np.log(max(len(best.faces), 1) / target)):
            best = level
        if abs(g - target) <= TOLERANCE * target or g == 0:
            break
        cell *= float(np.clip(np.sqrt(g / target), 0.5, 2.0))
    return best


def levels_of(tess, objects: np.ndarray, targets=None) -> list[Level]:
    """The coarser levels, finest first: ``targets`` (faces) or, by default,
    a quarter of the faces of the level before down to about MIN_FACES (none
    for a mesh of fewer than 2 x MIN_FACES faces)."""
    faces = np.asarray(tess.faces, np.int64)
    if targets is None:
        targets, g = [], len(faces) / FACES_STEP
        while g >= MIN_FACES:
            targets.append(int(g))
            g /= FACES_STEP
        if not targets and len(faces) >= 2 * MIN_FACES:
            targets = [MIN_FACES]
    area = vertex_areas(tess.vertices, faces)
    out = []
    for t in sorted(targets, reverse=True):
        if t >= len(faces):
            continue
        level = level_for(tess.vertices, tess.normals, faces, objects, area, t)
        if len(level.faces) and (not out or len(level.faces) < len(out[-1].faces)):
            out.append(level)
    return out


MAGIC = b"OGVL"


def levels_bytes(levels: list[Level]) -> bytes:
    """The levels as the page loads them (the module's layout)."""
    out = [struct.pack("<4sI", MAGIC, len(levels))]
    for lv in levels:
        out += [struct.pack("<IIfI", len(lv.positions), len(lv.faces), lv.cell, 0),
                np.ascontiguousarray(lv.positions, "<f4").tobytes(), np.ascontiguousarray(lv.objects, "<u4").tobytes(),
                np.ascontiguousarray(lv.faces, "<u4").tobytes()]
    return b"".join(out)
