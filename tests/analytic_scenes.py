"""Scenes with closed-form irradiance, shared by the tests.

1. A point light of intensity I at height h over a large plane, direct light
   only: E = I cos(theta) / r^2. The plane may reflect (albedo > 0): a plane
   cannot light itself, so reflected photons leave and E is unchanged.
2. A closed box whose walls all emit Le and reflect with albedo rho, all
   bounces (a furnace): the radiance is Le / (1 - rho) everywhere, so the
   irradiance is E = pi Le / (1 - rho).
"""

import math

import numpy as np

import oclgi

H = 1.0  # light height
INTENSITY = 1.0  # W/sr


def grid(n_cells, half):
    """A square grid in the y = 0 plane, 2 triangles per cell, normals +y."""
    xs = np.linspace(-half, half, n_cells + 1)
    xx, zz = np.meshgrid(xs, xs, indexing="ij")
    v = np.stack([xx.ravel(), np.zeros(xx.size), zz.ravel()], axis=1)
    idx = np.arange(xx.size).reshape(n_cells + 1, n_cells + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])
    return v, faces


def quad(y, half, albedo=0.5, **keys):
    """A mesh table: the square of half-side ``half`` in the plane y, facing
    up (+y), its albedo grey, and ``keys``."""
    return {"vertices": [[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]],
            "faces": [[0, 2, 1], [0, 3, 2]], "albedo": [albedo] * 3, **keys}


def translation(x, y=0.0, z=0.0):
    """The 4 x 4 pose moving an object by (x, y, z)."""
    m = np.eye(4)
    m[:3, 3] = [x, y, z]
    return m


def square(half, y=0.0):
    """(vertices, faces): the square of half-side ``half`` in the plane y, normal +y."""
    v = np.array([[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]], float)
    return v, np.array([[0, 3, 2], [0, 2, 1]])


def on_plane(xz, y=0.0, ny=1.0):
    """(n, 6) points of the plane y at ``xz`` (n, 2), facing +y (``ny`` -1: facing -y)."""
    xz = np.asarray(xz, float)
    n = len(xz)
    return np.column_stack([xz[:, 0], np.full(n, y), xz[:, 1], np.zeros(n), np.full(n, float(ny)), np.zeros(n)])


def plane_scene(n_cells, half, albedo=0.0):
    v, f = grid(n_cells, half)
    return oclgi.load_dict({
        "mesh": [{"vertices": v, "faces": f, "albedo": [albedo] * 3}],
        "point_light": [{"position": [0, H, 0], "intensity": [INTENSITY] * 3}],
        "photons": {"count": 1_000_000, "seed": 3, "max_depth": 2},
    })


def ring_points(rho=(0.0, 0.25, 0.5, 0.75, 1.0)):
    """Points of the plane y = 0 at the radii ``rho``, five angles each:
    (positions, the (n, 6) points facing up)."""
    p = np.array([(r * math.cos(a), 0.0, r * math.sin(a)) for r in rho for a in (0.0, 1.3, 2.6, 3.9, 5.2)])
    return p, np.hstack([p, np.tile([0.0, 1.0, 0.0], (len(p), 1))])


def exact(x, z):
    r2 = x * x + z * z + H * H
    return INTENSITY * H / r2**1.5


def disc_mean(x0, z0, d, n=200, f=exact):
    """Mean of f(x, z), the exact irradiance unless given, over the disc of
    radius d about (x0, z0) (midpoint rule, polar)."""
    r = (np.arange(n) + 0.5) / n * d
    phi = (np.arange(n) + 0.5) / n * 2 * np.pi
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    return float((f(x0 + rr * np.cos(pp), z0 + rr * np.sin(pp)) * rr).sum() / rr.sum())


def triangle_mean(tri, n=60):
    """Mean of the exact irradiance over a triangle (barycentric grid)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    keep = i + j < n
    u, v = (i[keep] + 1 / 3) / n, (j[keep] + 1 / 3) / n
    p = tri[0] + u[:, None] * (tri[1] - tri[0]) + v[:, None] * (tri[2] - tri[0])
    return float(exact(p[:, 0], p[:, 2]).mean())


def box_mesh(lo, hi, inward=None):
    """The box [lo, hi]: its 8 corners (x slowest, z fastest) and 12
    triangles, two a face; ``inward`` True (False) winds every normal to
    point into (out of) the box."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    if inward is not None:
        tri = v[faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        flip = (np.einsum("ij,ij->i", n, v.mean(axis=0) - tri.mean(axis=1)) < 0) == inward
        faces[flip] = faces[flip][:, ::-1]
    return v, faces


def box(rho, le):
    """Unit cube, faces wound so that normals point inwards (emission inwards)."""
    v, faces = box_mesh((0, 0, 0), (1, 1, 1), inward=True)
    return oclgi.load_dict({
        "mesh": [{"vertices": v, "faces": faces, "albedo": [rho] * 3, "emission": [le] * 3}],
        "photons": {"count": 1_000_000, "seed": 11, "max_depth": 32},
    })


def face_points(rng, n_per_face=6, margin=0.15):
    """Random points on the box's six faces, at least ``margin`` from the edges, normals inwards."""
    pts, nrm = [], []
    for axis in range(3):
        for side in (0.0, 1.0):
            p = margin + (1 - 2 * margin) * rng.random((n_per_face, 3))
            p[:, axis] = side
            n = np.zeros((n_per_face, 3))
            n[:, axis] = 1.0 if side == 0.0 else -1.0
            pts.append(p)
            nrm.append(n)
    return np.vstack(pts), np.vstack(nrm)
