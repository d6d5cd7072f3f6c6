"""The scene's surfaces cut into small triangles: view-independent query points.

Density estimation gives irradiance anywhere on a surface, so a solution
need not belong to one image: kept at the vertices of a finely tessellated
copy of the scene, it can be drawn from any viewpoint (a WebGL viewer) or
written into a file other tools open (a baked glTF), and orbiting a camera
costs nothing. Each triangle is cut uniformly into m x m triangles, m the
smallest number that brings its longest edge down to the target ``edge``
(by default the disc radius, so that neighbouring vertices are about one
disc apart: finer only blurs less than the estimate itself does).

Vertices are shared where triangles meet smoothly and share a material
(positions welded on a grid far finer than the edge, normals within
CREASE); at a crease or a material boundary each side keeps its own
vertex, so colour does not bleed across a wall-floor seam. Each vertex
remembers a source triangle and its barycentrics there: its query point
carries them (so points on a movable object follow it,
oclgi/incremental/attached_points.py); its normal is the mean of its
corners' triangle normals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import OclgiError

MAX_VERTICES = 20_000_000  # before welding; a finer tessellation is refused with its count
WELD = 1e-9  # position grid, times the scene's diagonal
CREASE = 30.0  # degrees: corners whose normals differ more stay apart (a crease)


@dataclass
class Tessellation:
    vertices: np.ndarray  # (V, 3) float64, the scene as loaded
    normals: np.ndarray  # (V, 3) float64, the mean of its corners' triangle normals
    faces: np.ndarray  # (F, 3) int64 into vertices
    face_source: np.ndarray  # (F,) int64: the scene triangle each face is part of
    vertex_tri: np.ndarray  # (V,) int64: a source triangle of each vertex
    vertex_barys: np.ndarray  # (V, 2) float64: its weights of the source's 2nd and 3rd corners
    edge: float

    def points(self):
        """The vertices as query points (kind "vertices", each with its source triangle)."""
        from ..queries import pack

        return pack(self.vertices, self.normals, self.vertex_tri, self.vertex_barys.astype(np.float32),
                    kind="vertices")


def _template(m: int):
    """Barycentric grid of one triangle cut m x m: (points (P, 2) of (i, j)
    with i + j <= m, faces (m^2, 3) into them, counter-clockwise as the
    source)."""
    ij = [(i, j) for j in range(m + 1) for i in range(m + 1 - j)]
    index = {p: k for k, p in enumerate(ij)}
    faces = []
    for j in range(m):
        for i in range(m - j):
            faces.append((index[i, j], index[i + 1, j], index[i, j + 1]))
            if i + j + 2 <= m:
                faces.append((index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]))
    return np.array(ij, np.int64), np.array(faces, np.int64)


def tessellate(scene, edge: float | None = None) -> Tessellation:
    """Cut every triangle of ``scene`` down to edges of at most ``edge``
    (default: the scene's disc radius)."""
    edge = float(scene.radius if edge is None else edge)
    diag = scene.diagonal
    if not (np.isfinite(edge) and edge > 0):
        raise OclgiError(f"the tessellation's edge length must be a positive number, got {edge!r}")
    v = scene.vertices[scene.faces]  # (F, 3, 3)
    longest = np.max(np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2), axis=1)
    cuts = np.maximum(np.ceil(longest / edge), 1)  # float64: a tiny edge must not overflow an integer
    total = float(((cuts + 1) * (cuts + 2) / 2).sum())
    if not total <= MAX_VERTICES:
        total = f"{total:,.0f}" if total < 1e18 else f"{total:.3g}"
        raise OclgiError(f"an edge of {edge:.4g} cuts the scene into {total} vertices (at most {MAX_VERTICES:,}); "
                         f"use a longer edge (the scene's diagonal is {diag:.4g})")
    m = cuts.astype(np.int64)
    normals = scene.triangle_normals()
    pos, nrm, src, bary, faces, face_src = [], [], [], [], [], []
    base = 0
    for mm in np.unique(m):
        tris = np.nonzero(m == mm)[0]
        ij, tf = _template(int(mm))
        w = ij / float(mm)  # (P, 2): weights of corners 1 and 2
        a, b, c = v[tris, 0], v[tris, 1], v[tris, 2]
        p = a[:, None] + w[None, :, 0, None] * (b - a)[:, None] + w[None, :, 1, None] * (c - a)[:, None]
        n_p = len(ij)
        pos.append(p.reshape(-1, 3))
        nrm.append(np.repeat(normals[tris], n_p, axis=0))
        src.append(np.repeat(tris, n_p))
        bary.append(np.tile(w, (len(tris), 1)))
        offs = base + n_p * np.arange(len(tris))
        faces.append((tf[None] + offs[:, None, None]).reshape(-1, 3))
        face_src.append(np.repeat(tris, len(tf)))
        base += n_p * len(tris)
    pos, nrm, src, bary = (np.concatenate(x) for x in (pos, nrm, src, bary))
    faces, face_src = np.concatenate(faces), np.concatenate(face_src)
    keep, inverse, nrm = _weld(pos, nrm, scene.tri_material[src], WELD * diag)
    return Tessellation(vertices=pos[keep], normals=nrm, faces=inverse[faces], face_source=face_src,
                        vertex_tri=src[keep], vertex_barys=bary[keep], edge=edge)


def _weld(pos, nrm, material, quantum: float):
    """Corners that are one vertex: at the same place (on a grid of
    ``quantum``), of the same material, and with source normals within
    CREASE of the first such corner's (so a curved mesh stays one surface
    and a wall meets the floor in two rows of vertices). Returns (the kept
    corner of each vertex, the vertex of each corner, the vertices' normals:
    the mean of their corners' source normals, area-weighting aside)."""
    q = np.round(pos / quantum).astype(np.int64)
    key = np.concatenate([q, material[:, None].astype(np.int64)], axis=1)
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.reshape(-1)
    vertex = np.full(len(pos), -1, np.int64)
    cos_crease = np.cos(np.radians(CREASE))
    n_vertices = 0
    while True:  # one cluster per group and pass: as many passes as a group has creases
        left = np.nonzero(vertex < 0)[0]
        if not len(left):
            break
        rep = np.full(group.max() + 1, -1, np.int64)
        rep[group[left[::-1]]] = left[::-1]  # the first corner left in each group
        r = rep[group[left]]
        join = np.einsum("ij,ij->i", nrm[left], nrm[r]) >= cos_crease
        reps = np.unique(r)
        ids = np.full(len(pos), -1, np.int64)
        ids[reps] = n_vertices + np.arange(len(reps))
        vertex[left[join]] = ids[r[join]]
        n_vertices += len(reps)
    # vertices numbered in the order their first corner comes: deterministic, local
    first = np.full(n_vertices, len(pos), np.int64)
    np.minimum.at(first, vertex, np.arange(len(pos)))
    order = np.argsort(first, kind="stable")
    rank = np.empty(n_vertices, np.int64)
    rank[order] = np.arange(n_vertices)
    vertex = rank[vertex]
    mean = np.zeros((n_vertices, 3))
    np.add.at(mean, vertex, nrm)
    mean /= np.linalg.norm(mean, axis=1)[:, None]
    return first[order], vertex, mean
