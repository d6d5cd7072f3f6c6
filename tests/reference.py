"""Slow, obvious float64 numpy references for the device code (tests only)."""

from __future__ import annotations

import numpy as np


def ray_triangle_brute(origins, dirs, tri_v, chunk=64):
    """Closest hit of every ray against every triangle (Moller-Trumbore, float64).

    Returns (t, tri): t = inf and tri = -1 for a miss.
    """
    o = np.asarray(origins, np.float64)
    d = np.asarray(dirs, np.float64)
    v0 = tri_v[:, 0].astype(np.float64)
    e1 = tri_v[:, 1] - v0
    e2 = tri_v[:, 2] - v0
    t_best = np.full(len(o), np.inf)
    tri_best = np.full(len(o), -1, np.int64)
    for a in range(0, len(o), chunk):
        oo, dd = o[a:a + chunk, None, :], d[a:a + chunk, None, :]
        p = np.cross(dd, e2[None])
        det = np.einsum("rtk,tk->rt", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = oo - v0[None]
            u = np.einsum("rtk,rtk->rt", s, p) * inv
            q = np.cross(s, e1[None])
            v = np.einsum("rtk,rtk->rt", np.broadcast_to(dd, q.shape), q) * inv
            t = np.einsum("tk,rtk->rt", e2, q) * inv
        ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        t = np.where(ok, t, np.inf)
        k = np.argmin(t, axis=1)
        t_best[a:a + chunk] = t[np.arange(len(k)), k]
        tri_best[a:a + chunk] = np.where(np.isfinite(t_best[a:a + chunk]), k, -1)
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
