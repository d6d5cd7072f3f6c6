"""The query points of the viewer: every static vertex, and movable objects' vertices thinned to the edge.

The tessellation cuts triangles down to the target edge but never joins
them, so a finely modelled movable object keeps all its vertices: the
Stanford bunny scaled into the Cornell box has 36k, about a millimetre
apart under discs of 3 cm. They are the session's dynamic points, summed
again over the whole store after every move, and their overlapping discs
are most of an update's time (bench/HISTORY.md, "Viewer": 408 against 35 ms
per move with and without them). Closer than the edge they only repeat one
another (each is the disc's mean irradiance), so a movable object is
queried at one vertex per cell of the edge's size (and per material and
normal's octant: the two sides of an ear stay apart), the one nearest the
mean of the cell's vertices, and each vertex shows its cell's value.
Static vertices, which the tessellation already placed about an edge apart,
are each a point of their own.
"""

from __future__ import annotations

import numpy as np


def object_points(tess, objects: np.ndarray, material: np.ndarray, all_vertices: bool = False):
    """(the vertices queried, for each vertex the index of its value among
    them); ``objects``: per vertex 0 (static) or its movable object's
    1-based rank; ``material``: per vertex its material."""
    n = len(tess.vertices)
    if all_vertices or not (objects > 0).any():
        return np.arange(n), np.arange(n)
    movable = np.nonzero(objects > 0)[0]
    pos, nrm = tess.vertices[movable], tess.normals[movable]
    # the normal's octant and largest axis: two normals of one class are at most 90 degrees apart
    side = 3 * ((nrm > 0) @ np.array([1, 2, 4])) + np.argmax(np.abs(nrm), axis=1)
    cell = np.floor(pos / tess.edge).astype(np.int64)
    key = np.column_stack([objects[movable], material[movable], side, cell])
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.reshape(-1)
    n_groups = group.max() + 1
    mean = np.zeros((n_groups, 3))
    np.add.at(mean, group, pos)
    mean /= np.bincount(group, minlength=n_groups)[:, None]
    d = np.linalg.norm(pos - mean[group], axis=1)
    order = np.lexsort((np.arange(len(group)), d, group))  # per group, nearest the mean first
    first = np.ones(len(order), bool)
    first[1:] = group[order][1:] != group[order][:-1]
    rep_of_group = np.empty(n_groups, np.int64)
    rep_of_group[group[order][first]] = movable[order][first]
    keep = np.zeros(n, bool)
    keep[objects == 0] = True
    keep[rep_of_group] = True
    queried = np.nonzero(keep)[0]
    index_of = np.full(n, -1, np.int64)
    index_of[queried] = np.arange(len(queried))
    value_of = index_of.copy()
    value_of[movable] = index_of[rep_of_group[group]]
    return queried, value_of
