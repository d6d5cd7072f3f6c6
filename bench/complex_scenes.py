"""Complex test scenes, generated (issue 16, item 4): geometry smaller than a
DETP disc, and occluders near walls.

``foliage(n_leaves)``  a tree over a ground plane, lit by a sun: a trunk, six
                       branches and ``n_leaves`` small two-sided leaf quads
                       (side 0.06 to 0.12, against a default disc radius of
                       1% of the 23-unit diagonal, 0.23) in an ellipsoidal
                       crown; 46,000 leaves make 101,272 triangles.
                       ``light="area"``: lit instead by a 6 x 6 square area
                       light 9 above the ground, facing down (2 more
                       triangles).
``arcade()``           a closed room (10 x 4 x 6) lit by a ceiling area
                       light: a row of columns with arches of thin tubes
                       (0.12 radius) and a lintel carrying a gallery's
                       ceiling in front of the back wall, and a pillar 0.15
                       from a side wall; about 24,500 triangles.

``courtyard()``         a closed two-storey building (20 x 8 x 16) around a
                       court open to the sky, lit by a sun through the
                       opening: on each storey a gallery behind a ring of
                       columns carrying arches of tubes (0.12 radius), the
                       first floor's slab with a parapet, the roof a ring
                       around the opening; about 110,000 triangles.
                       ``light="sky"``: lit instead by a uniform sky above
                       the horizon, through the opening.

``points(scene, kind, n, rng)`` draws query points on the scenes' parts
(each with its triangle and the side its triangle faces, leaves on a random
side), so a benchmark sees the hard places as often as the easy ones.

Every mesh is wound so its triangles' normals face the side that is lit
(outward from solids, into the room), and the meshes are built here with
numpy: nothing is shipped.
"""

from __future__ import annotations

import numpy as np

import oclgi
from oclgi.queries import QueryPoints


def grid(origin, u, v, nu, nv):
    """A parallelogram origin + s u + t v, s, t in [0, 1], cut into nu x nv
    cells of two triangles; normal u x v."""
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    verts = np.asarray(origin, float) + s.reshape(-1, 1) * np.asarray(u, float) + t.reshape(-1, 1) * np.asarray(v, float)
    idx = np.arange(verts.shape[0]).reshape(nu + 1, nv + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return verts, faces


def box(lo, hi, cells=1):
    """A closed box, normals outward."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    e = hi - lo
    x, y, z = np.diag(e)
    parts = [grid(lo, z, y, cells, cells), grid(lo + x, y, z, cells, cells),  # -x, +x
             grid(lo, x, z, cells, cells), grid(lo + y, z, x, cells, cells),  # -y, +y
             grid(lo, y, x, cells, cells), grid(lo + z, x, y, cells, cells)]  # -z, +z
    return merge(parts)


def cylinder(base, axis, radius, segments=16, rings=1, caps=True):
    """A tube of ``radius`` from ``base`` along ``axis`` (its length),
    normals outward; closed by caps."""
    base, axis = np.asarray(base, float), np.asarray(axis, float)
    h = np.linalg.norm(axis)
    a = axis / h
    t = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    t /= np.linalg.norm(t)
    b = np.cross(a, t)
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b
    hs = np.linspace(0, 1, rings + 1)
    verts = (base + hs[:, None, None] * axis + radius * ring[None]).reshape(-1, 3)
    i = np.arange(rings * segments)  # each quad: i, j along a ring, i + segments, j + segments on the next
    j = i - i % segments + (i + 1) % segments
    parts = [(verts, np.stack([i, j, j + segments, i, j + segments, i + segments], 1).reshape(-1, 3))]
    if caps:
        for end, sign in ((0, -1), (rings, 1)):
            centre = base + hs[end] * axis
            v = np.vstack([centre, verts[end * segments:(end + 1) * segments]])
            k = np.arange(segments)
            f = np.stack([np.zeros(segments, int), 1 + k, 1 + (k + 1) % segments], 1)
            parts.append((v, f if sign > 0 else f[:, ::-1]))
    return merge(parts)


def arch(centre, span_axis, up, major, minor, segments=24, sides=10):
    """Half a torus (the upper half) in the plane of span_axis and up: an
    arch tube of radius ``minor`` over a span of 2 ``major``; normals outward."""
    c, e1, e2 = np.asarray(centre, float), np.asarray(span_axis, float), np.asarray(up, float)
    e3 = np.cross(e1, e2)
    th = np.linspace(0, np.pi, segments + 1)
    ph = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    out = []
    for t in th:
        radial = np.cos(t) * e1 + np.sin(t) * e2
        ring = c + major * radial + minor * (np.cos(ph)[:, None] * radial + np.sin(ph)[:, None] * e3)
        out.append(ring)
    i = np.arange(segments * sides)  # each quad: i, j round a ring, i + sides, j + sides on the next
    j = i - i % sides + (i + 1) % sides
    return np.concatenate(out), np.stack([i, j + sides, j, i, i + sides, j + sides], 1).reshape(-1, 3)


def merge(parts):
    """One mesh of the (vertices, faces) ``parts``."""
    base = np.cumsum([0] + [len(v) for v, _ in parts])
    return np.concatenate([v for v, _ in parts]), np.concatenate([np.asarray(f) + b for (_, f), b in zip(parts, base)])


def mesh(name, geometry, grey, **extra) -> dict:
    """A scene dict's mesh: (vertices, faces) or a list of them, merged; a grey albedo."""
    v, f = merge(geometry) if isinstance(geometry, list) else geometry
    return {"name": name, "vertices": v, "faces": f, "albedo": [grey] * 3, **extra}


def scene(name, meshes, **extra) -> oclgi.Scene:
    return oclgi.load_dict({"name": name, "mesh": meshes, "photons": {"count": 1_000_000, "seed": 1, "max_depth": 8},
                            **extra})


def leaves(rng, n, centre, radii, side=(0.06, 0.12)):
    """n square leaves (two triangles each), random sizes and orientations, in an ellipsoid."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    c = np.asarray(centre) + u * rng.random((n, 1)) ** (1 / 3) * np.asarray(radii)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    a = np.cross(nrm, rng.normal(size=(n, 3)))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(nrm, a)
    h = 0.5 * rng.uniform(*side, size=(n, 1))
    corners = np.stack([c - h * a - h * b, c + h * a - h * b, c + h * a + h * b, c - h * a + h * b], 1)
    verts = corners.reshape(-1, 3)
    k = 4 * np.arange(n)
    faces = np.concatenate([np.stack([k, k + 1, k + 2], 1), np.stack([k, k + 2, k + 3], 1)])
    return verts, faces


# the lights of the scenes' variants (the module's docstring)
SUN = {"sun": [{"direction": [0.35, -1.0, 0.25], "irradiance": [3.0, 3.0, 3.0]}]}
AREA_LIGHT = grid([-3.0, 9.0, -3.0], [6.0, 0, 0], [0, 0, 6.0], 1, 1)  # normal -y: faces down
SKY = {"sky": {"radiance": [1.0, 1.0, 1.0], "hemisphere": True}}


def foliage(n_leaves: int = 46_000, seed: int = 16, light: str = "sun") -> oclgi.Scene:
    """The tree scene (see the module's docstring); parts named ground,
    wood, leaves (and light, under the area light)."""
    rng = np.random.default_rng(seed)
    ground = grid([-8, 0, 8], [16, 0, 0], [0, 0, -16], 64, 64)  # normal +y
    wood = [cylinder([0, 0, 0], [0, 2.6, 0], 0.15, 20, 8)]
    for k in range(6):
        ang = 2 * np.pi * k / 6 + 0.3
        d = np.array([np.cos(ang), 0.7, np.sin(ang)])
        wood.append(cylinder([0, 2.2 + 0.07 * k, 0], 1.3 * d / np.linalg.norm(d), 0.05, 12, 4))
    crown = leaves(rng, n_leaves, [0, 3.5, 0], [1.7, 1.1, 1.7])
    meshes = [mesh("ground", ground, 0.35), mesh("wood", wood, 0.3), mesh("leaves", crown, 0.5)]
    if light == "area":
        return scene(f"foliage{n_leaves}_area", meshes + [mesh("light", AREA_LIGHT, 0.0, emission=[7.0] * 3)])
    return scene(f"foliage{n_leaves}", meshes, **SUN)


def arcade() -> oclgi.Scene:
    """The closed room with columns, arches, a gallery and a pillar by a wall."""
    W, H, D = 10.0, 4.0, 6.0
    n = 48  # cells per wall side
    # walls wound to face into the room
    floor = grid([0, 0, D], [W, 0, 0], [0, 0, -D], n, n)  # normal +y
    ceiling = grid([0, H, 0], [W, 0, 0], [0, 0, D], n, n)  # normal -y
    back = grid([0, 0, 0], [W, 0, 0], [0, H, 0], n, n // 2)  # z = 0, normal +z
    front = grid([W, 0, D], [-W, 0, 0], [0, H, 0], n, n // 2)  # z = D, normal -z
    left = grid([0, 0, D], [0, 0, -D], [0, H, 0], n, n // 2)  # x = 0, normal +x
    right = grid([W, 0, 0], [0, 0, D], [0, H, 0], n, n // 2)  # x = W, normal -x
    walls = [back, front, left, right, ceiling]
    xs = np.linspace(1.5, 8.5, 6)
    zc = 1.4
    solids = [cylinder([x, 0, zc], [0, 3.0, 0], 0.2, 32, 6) for x in xs]
    solids.append(box([1.0, 3.0, 0.0], [9.0, 3.3, zc + 0.25], 8))  # lintel and gallery ceiling
    solids += [arch([0.5 * (a + b), 2.3, zc], [1, 0, 0], [0, 1, 0], 0.5 * (b - a) - 0.2, 0.12)
               for a, b in zip(xs[:-1], xs[1:])]
    solids.append(box([W - 0.55, 0.0, 3.8], [W - 0.15, 3.0, 4.2], 4))  # a pillar 0.15 from the wall
    light = grid([4.0, H - 0.01, 3.0], [2.0, 0, 0], [0, 0, 1.5], 1, 1)  # normal -y: faces down
    return scene("arcade", [mesh("floor", floor, 0.5), mesh("walls", walls, 0.6), mesh("stone", solids, 0.55),
                            mesh("light", light, 0.0, emission=[12.0, 12.0, 12.0])])


def courtyard(light: str = "sun") -> oclgi.Scene:
    """The two-storey courtyard (see the module's docstring); parts named
    floor (the ground floor), walls (outer walls and the roof's underside)
    and stone (columns, arches, the gallery slab and its parapet)."""
    W, D, H1, H = 20.0, 16.0, 4.0, 8.0  # footprint, first floor, roof
    g = 3.0  # gallery depth: the column ring stands g inside the outer walls
    floor = grid([0, 0, D], [W, 0, 0], [0, 0, -D], 80, 64)  # normal +y
    walls = [grid([0, 0, 0], [W, 0, 0], [0, H, 0], 80, 32),  # z = 0, normal +z
             grid([W, 0, D], [-W, 0, 0], [0, H, 0], 80, 32),  # z = D, normal -z
             grid([0, 0, D], [0, 0, -D], [0, H, 0], 64, 32),  # x = 0, normal +x
             grid([W, 0, 0], [0, 0, D], [0, H, 0], 64, 32)]  # x = W, normal -x
    # the roof: a ring around the court's opening, facing down
    walls += [grid([0, H, 0], [W, 0, 0], [0, 0, g], 80, 12), grid([0, H, D - g], [W, 0, 0], [0, 0, g], 80, 12),
              grid([0, H, g], [g, 0, 0], [0, 0, D - 2 * g], 12, 40),
              grid([W - g, H, g], [g, 0, 0], [0, 0, D - 2 * g], 12, 40)]
    # the first floor's gallery slab (0.3 thick) and a parapet 0.3 in front of the columns
    slab_lo, slab_hi = H1 - 0.3, H1
    stone = [box(lo, hi, 16) for lo, hi in (([0, slab_lo, 0], [W, slab_hi, g]), ([0, slab_lo, D - g], [W, slab_hi, D]),
                                            ([0, slab_lo, g], [g, slab_hi, D - g]),
                                            ([W - g, slab_lo, g], [W, slab_hi, D - g]))]
    t = 0.15
    stone += [box(lo, hi, 8) for lo, hi in (([g - 0.3, H1, g - 0.3 - t], [W - g + 0.3, H1 + 1.0, g - 0.3]),
                                            ([g - 0.3, H1, D - g + 0.3], [W - g + 0.3, H1 + 1.0, D - g + 0.3 + t]),
                                            ([g - 0.3 - t, H1, g - 0.3], [g - 0.3, H1 + 1.0, D - g + 0.3]),
                                            ([W - g + 0.3, H1, g - 0.3], [W - g + 0.3 + t, H1 + 1.0, D - g + 0.3]))]
    # the column ring, 2 m bays: 8 columns along x, 6 along z (corners shared)
    xs, zs = np.linspace(g, W - g, 8), np.linspace(g, D - g, 6)
    ring = [(x, g) for x in xs] + [(x, D - g) for x in xs] + [(g, z) for z in zs[1:-1]] + [(W - g, z) for z in zs[1:-1]]
    bays = [((a, g), (b, g)) for a, b in zip(xs[:-1], xs[1:])] + [((a, D - g), (b, D - g)) for a, b in zip(xs[:-1], xs[1:])]
    bays += [((g, a), (g, b)) for a, b in zip(zs[:-1], zs[1:])] + [((W - g, a), (W - g, b)) for a, b in zip(zs[:-1], zs[1:])]
    for y0, y1, rc in ((0.0, slab_lo, 0.22), (H1, H, 0.18)):
        stone += [cylinder([x, y0, z], [0, y1 - y0, 0], rc, 36, 8) for x, z in ring]
        for (ax, az), (bx, bz) in bays:
            span = np.array([bx - ax, 0.0, bz - az])
            half = 0.5 * np.linalg.norm(span)
            major, minor = half - rc, 0.12
            centre = [0.5 * (ax + bx), y1 - major - minor, 0.5 * (az + bz)]
            stone.append(arch(centre, span / (2 * half), [0, 1, 0], major, minor, 32, 12))
    meshes = [mesh("floor", floor, 0.45), mesh("walls", walls, 0.6), mesh("stone", stone, 0.55)]
    if light == "sky":
        return scene("courtyard_sky", meshes, **SKY)
    return scene("courtyard", meshes, sun=[{"direction": [0.45, -1.0, 0.3], "irradiance": [3.0, 3.0, 3.0]}])


def part(scene, k: int) -> np.ndarray:
    """The triangles of the scene's k-th mesh (each mesh has its own material here)."""
    return np.nonzero(scene.tri_material == k)[0]


def points(scene, groups: dict, rng) -> QueryPoints:
    """Query points: ``groups`` maps a triangle-id array (a part of the
    scene) to (count, side), side "up" (the triangle's normal) or "both"
    (either side at random: two-sided leaves); uniform over each part's area."""
    tri_all, p_all, n_all = [], [], []
    areas = scene.triangle_areas()
    normals = scene.triangle_normals()
    for ids, (count, side) in groups.items():
        ids = np.asarray(ids)
        w = areas[ids] / areas[ids].sum()
        tri = ids[rng.choice(len(ids), count, p=w)]
        b = rng.dirichlet([1, 1, 1], count)
        p = np.einsum("rk,rkc->rc", b, scene.vertices[scene.faces[tri]])
        nrm = normals[tri].copy()
        if side == "both":
            nrm *= np.where(rng.random(count) < 0.5, 1.0, -1.0)[:, None]
        tri_all.append(tri), p_all.append(p), n_all.append(nrm)
    tri, p, nrm = np.concatenate(tri_all), np.concatenate(p_all), np.concatenate(n_all)
    pos, n4 = (np.pad(a.astype(np.float32), ((0, 0), (0, 1))) for a in (p, nrm))
    pos[:, 3] = tri.astype(np.int32).view(np.float32)
    return QueryPoints(pos, n4, np.zeros((len(p), 2), np.float32))
