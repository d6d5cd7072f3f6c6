"""Slow, obvious float64 numpy references for the device code (tests only)."""

from __future__ import annotations

import numpy as np


def ray_triangle_brute(origins, dirs, tri_v, chunk=32, block=4096):
    """Closest hit of every ray against every triangle (Moller-Trumbore, float64).

    Every (ray, triangle) pair is looked at: a pair whose ray passes farther
    from the triangle's centroid than its farthest corner cannot hit it (the
    triangle lies in that ball), and the others are intersected exactly, so
    that the work per pair is a dozen operations, not the intersection's
    fifty. Ties at the same t go to the lowest triangle index.

    Returns (t, tri): t = inf and tri = -1 for a miss.
    """
    o = np.asarray(origins, np.float64)
    d = np.asarray(dirs, np.float64)
    tri_v = np.asarray(tri_v, np.float64)
    v0 = tri_v[:, 0]
    e1 = tri_v[:, 1] - v0
    e2 = tri_v[:, 2] - v0
    centre = tri_v.mean(axis=1)
    # the ball's radius, a hair larger so that rounding cannot drop a grazing pair
    r2 = (np.linalg.norm(tri_v - centre[:, None], axis=2).max(axis=1) * (1 + 1e-9) + 1e-12) ** 2
    t_best = np.full(len(o), np.inf)
    tri_best = np.full(len(o), -1, np.int64)
    for a in range(0, len(o), chunk):
        oo, dd = o[a:a + chunk], d[a:a + chunk]
        pairs = []
        for b in range(0, len(tri_v), block):  # blocks of triangles: the temporaries stay in cache
            c, rr = centre[b:b + block], r2[b:b + block]
            wx, wy, wz = c[:, 0] - oo[:, 0, None], c[:, 1] - oo[:, 1, None], c[:, 2] - oo[:, 2, None]
            along = wx * dd[:, 0, None] + wy * dd[:, 1, None] + wz * dd[:, 2, None]
            w2 = wx * wx + wy * wy + wz * wz
            # the half-line's nearest point to the centre: at t = along, or the origin when along < 0
            ray, tri = np.nonzero(((along >= 0) & (w2 - along * along <= rr)) | (w2 <= rr))
            pairs.append((ray, tri + b))
        ray, tri = np.concatenate([p[0] for p in pairs]), np.concatenate([p[1] for p in pairs])
        if len(ray) == 0:
            continue
        dv, s = dd[ray], oo[ray] - v0[tri]
        p = np.cross(dv, e2[tri])
        det = np.einsum("nk,nk->n", p, e1[tri])
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            u = np.einsum("nk,nk->n", s, p) * inv
            q = np.cross(s, e1[tri])
            v = np.einsum("nk,nk->n", dv, q) * inv
            t = np.einsum("nk,nk->n", e2[tri], q) * inv
        ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        ray, tri, t = ray[ok], tri[ok], t[ok]
        order = np.lexsort((tri, t, ray))  # by ray, then t, then triangle
        first = order[np.r_[True, ray[order][1:] != ray[order][:-1]]] if len(order) else order
        t_best[a + ray[first]] = t[first]
        tri_best[a + ray[first]] = tri[first]
    return t_best, tri_best


def detp_reference(points, normals, segments, radius, ext, count_emitted=True, max_depth=None):
    """Plain DETP in float64: summed power (n, 3) of the segments crossing each disc."""
    seg = segments
    o = seg["org"].astype(np.float64)
    w = seg["dir"].astype(np.float64)
    t_end = seg["t_end"].astype(np.float64)
    power = seg["power"].astype(np.float64)
    keep = np.linalg.norm(w, axis=1) > 0
    if not count_emitted:
        keep &= (np.arange(len(seg)) % max_depth) != 0
    o, w, t_end, power = o[keep], w[keep], t_end[keep], power[keep]
    out = np.zeros((len(points), 3))
    for i, (x, n) in enumerate(zip(np.asarray(points, np.float64), np.asarray(normals, np.float64))):
        wn = w @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((x - o) @ n) / wn
        c = o + t[:, None] * w - x
        hit = (wn < -1e-6) & (t > 0) & (t <= t_end + ext) & (np.einsum("ij,ij->i", c, c) <= radius**2)
        out[i] = power[hit].sum(axis=0)
    return out


def fresnel_dielectric(cos_i: float, eta: float) -> float:
    """Unpolarised Fresnel reflectance (cos_i >= 0 on the incident side, eta =
    eta_t / eta_i); 1 under total internal reflection."""
    sin2_t = (1 - cos_i ** 2) / eta ** 2
    if sin2_t >= 1:
        return 1.0
    ct = np.sqrt(1 - sin2_t)
    rs = (cos_i - eta * ct) / (cos_i + eta * ct)
    rp = (eta * cos_i - ct) / (eta * cos_i + ct)
    return float(0.5 * (rs ** 2 + rp ** 2))


def ies_candela(vertical, horizontal, candela, gamma, c):
    """An IES type C table's intensity in directions (gamma, C), degrees, as
    oclgi defines it (bins centred on the tabulated angles, so: the value at
    the nearest tabulated angle), straight from the file's table: the
    horizontal angles ``horizontal`` as the file gives them (last 0, 90,
    180 or 360), folded by the symmetry they state, not expanded; 0 outside
    the vertical angles' range."""
    vertical, horizontal = np.asarray(vertical, np.float64), np.asarray(horizontal, np.float64)
    table = np.asarray(candela, np.float64).reshape(len(horizontal), len(vertical))
    gamma, c = np.broadcast_arrays(np.asarray(gamma, np.float64), np.asarray(c, np.float64))
    c = np.mod(c, 360.0)
    last = horizontal[-1]
    if last <= 180:  # bilateral (or finer): C and 360 - C alike
        c = np.where(c > 180, 360 - c, c)
    if last <= 90:  # quadrant: C and 180 - C alike
        c = np.where(c > 90, 180 - c, c)
    if last == 0:
        c = np.zeros_like(c)
    # nearest horizontal angle on the circle (360 wraps onto 0 when the table is whole)
    dc = np.abs(c[..., None] - horizontal)
    if last == 360:
        dc = np.minimum(dc, 360 - dc)
    j = np.argmin(dc, axis=-1)
    i = np.argmin(np.abs(gamma[..., None] - vertical), axis=-1)
    inside = (gamma >= vertical[0]) & (gamma <= vertical[-1])
    return np.where(inside, table[j, i], 0.0)
