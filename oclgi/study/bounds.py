"""Theoretical variance bounds of the estimators (DESIGN.md section 3, "Efficiency").

The estimator study checks measured variances against these and compares
estimators by efficiency = 1 / (time * variance).

Impact Count (Shirley 1992). A zone's estimate is the power landing on it
over its area; Shirley bounds its variance for N zones whose area ratio
(largest over smallest) is at most K, so no zone is smaller than A / (K N).
The vertex estimate of a triangle (a, b, c) averages the triangles around
its vertices: n_va + n_vb + n_vc - 5 distinct triangles on a manifold mesh
(the triangle itself is counted three times, its three edge neighbours
twice), which divides the variance:

    Var <= N R_max L_max Phi_T^2 K / ((1 - R_max) pi (n_va + n_vb + n_vc - 5) A n_R)

Photon Maps (order statistics, Papadatos 1995). r_k is the k-th order
statistic of the n_R impact distances; Papadatos' sharp bound on the
variance of the k-th of n order statistics, in units of the parent's
variance, is

    sigma^2_n(k) = sup_{0<x<1} I_x(k, n+1-k) (1 - I_x(k, n+1-k)) / (x (1 - x))

(I_x the regularised incomplete beta function; two-point parents reach
it: for a Bernoulli(x) parent the k-th largest of n is 1 when at least k
draws are, so it is Bernoulli(I_x(k, n+1-k)) and its variance over x (1 - x)
is the integrand; the k-th smallest has the same sup by symmetry), and

    Var <= sigma^2_{n_R}(k) R_max / ((1 - R_max) pi A) L_max Phi_T^2 / n_R

DETP (Lastra et al. 2002), disc radius d:

    Var <= R_max / ((1 - R_max) pi^2 d^2) L_max Phi_T^2 / n_R

Finding the sup. With u = logit(x), x = expit(u) and 1 - x = expit(-u) are
both accurate near 0 and 1, and 1 - I_x(a, b) = I_{1-x}(b, a) is evaluated
directly, so nothing cancels. The integrand g is evaluated on a grid of u
spaced evenly over [-L, L], x from 1e-4/n to 1 - 1e-4/n (g peaks near
x = (k-1)/(n-1) with a relative width about 1/sqrt(k), several grid steps
even at n = 10^9); the best grid point is refined by a bounded scalar
maximiser between its two neighbours. The boundary limits are added as
candidates: g -> n as x -> 0 when k = 1 (I_x(1, n) = 1 - (1 - x)^n ~ n x) and
as x -> 1 when k = n, else g -> 0 at both ends; for k = 1 the sup is that
limit, n, approached but not attained.

Parameters (all functions):

    ==========  ==========================================================
    n_rays      n_R, the number of photon paths (segments) traced
    r_max       R_max, the largest reflectance in the scene, 0 <= R_max < 1
    l_max       L_max, the largest radiance (the bounds' scale of L)
    phi_total   Phi_T, the total emitted power
    area        A, the total surface area of the scene
    d           the DETP disc radius
    k           the Photon Map's neighbour count, 1 <= k <= n_R
    n_zones     N, the number of zones (patches) of Impact Count
    area_ratio  K, largest zone area over smallest
    n_va ...    n_va, n_vb, n_vc: triangles around each vertex of the
                triangle holding the point (their sum minus 5 >= 1)
    ==========  ==========================================================
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import betainc, expit

from ..errors import OclgiError

GRID_POINTS = 4001
TAIL = 1e-4  # grid reaches x = TAIL / n from both ends


def _check_nk(n, k):
    for name, v in (("n", n), ("k", k)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise OclgiError(f"{name} must be an integer, got {v!r}")
    if not 1 <= k <= n:
        raise OclgiError(f"need 1 <= k <= n, got n = {n}, k = {k}")


def order_statistic_integrand(x, n: int, k: int):
    """g(x) = I_x(k, n+1-k) (1 - I_x(k, n+1-k)) / (x (1 - x)), for 0 < x < 1."""
    _check_nk(n, k)
    x = np.asarray(x, dtype=np.float64)
    return _g(x, 1.0 - x, n, k)


def _g(x, y, n, k):
    """g with x and y = 1 - x given separately (accurate both ends)."""
    i = betainc(k, n + 1 - k, x)
    j = betainc(n + 1 - k, k, y)  # 1 - I_x(k, n+1-k), without cancellation
    return i * j / (x * y)


def _g_logit(u, n, k):
    return _g(expit(u), expit(-u), n, k)


def order_statistic_factor(n: int, k: int, return_argmax: bool = False):
    """Papadatos' sigma^2_n(k): the largest variance of the k-th of n order
    statistics per unit variance of the parent (module docstring).

    With ``return_argmax``, returns (sigma2, x*) with x* where the sup is
    reached (0.0 or 1.0 when it is a boundary limit: k = 1 or k = n).
    """
    _check_nk(n, k)
    n, k = int(n), int(k)
    half = math.log(n / TAIL)  # logit(1 - TAIL/n) ~ log(n/TAIL)
    u = np.linspace(-half, half, GRID_POINTS)
    g = _g_logit(u, n, k)
    i = int(np.argmax(g))
    lo, hi = u[max(i - 1, 0)], u[min(i + 1, len(u) - 1)]
    best_u, best = u[i], float(g[i])
    if hi > lo:
        res = minimize_scalar(lambda t: -float(_g_logit(np.float64(t), n, k)), bounds=(lo, hi),
                              method="bounded", options={"xatol": 1e-10})
        if -res.fun > best:
            best_u, best = float(res.x), float(-res.fun)
    x_best = float(expit(best_u))
    # boundary limits (k = 1 at x -> 0, k = n at x -> 1): the value n
    if k == 1 and n >= best:
        best, x_best = float(n), 0.0
    if k == n and n >= best:
        best, x_best = float(n), 1.0
    return (best, x_best) if return_argmax else best


def _positive(**kw):
    for name, v in kw.items():
        if not (isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
                and math.isfinite(v) and v > 0):
            raise OclgiError(f"{name} must be a positive number, got {v!r}")


def _reflectance(r_max):
    if not (isinstance(r_max, (int, float, np.integer, np.floating)) and 0 <= r_max < 1):
        raise OclgiError(f"r_max must be in [0, 1), got {r_max!r}")


def detp_bound(r_max: float, l_max: float, phi_total: float, d: float, n_rays: int) -> float:
    """DETP: R_max / ((1 - R_max) pi^2 d^2) L_max Phi_T^2 / n_R."""
    _reflectance(r_max)
    _positive(l_max=l_max, phi_total=phi_total, d=d, n_rays=n_rays)
    return r_max / ((1 - r_max) * math.pi**2 * d**2) * l_max * phi_total**2 / n_rays


def photon_map_bound(r_max: float, l_max: float, phi_total: float, area: float, n_rays: int,
                     k: int) -> float:
    """Photon Maps: sigma^2_{n_R}(k) R_max / ((1 - R_max) pi A) L_max Phi_T^2 / n_R."""
    _reflectance(r_max)
    _positive(l_max=l_max, phi_total=phi_total, area=area, n_rays=n_rays)
    s2 = order_statistic_factor(n_rays, k)
    return s2 * r_max / ((1 - r_max) * math.pi * area) * l_max * phi_total**2 / n_rays


def impact_count_bound(r_max: float, l_max: float, phi_total: float, area: float, n_rays: int,
                       n_zones: int, area_ratio: float, n_va: int, n_vb: int, n_vc: int) -> float:
    """Impact Count (Shirley 1992), vertex-averaged:
    N R_max L_max Phi_T^2 K / ((1 - R_max) pi (n_va + n_vb + n_vc - 5) A n_R)."""
    _reflectance(r_max)
    _positive(l_max=l_max, phi_total=phi_total, area=area, n_rays=n_rays, n_zones=n_zones)
    if not (isinstance(area_ratio, (int, float, np.integer, np.floating)) and area_ratio >= 1):
        raise OclgiError(f"area_ratio (largest over smallest zone) must be >= 1, got {area_ratio!r}")
    around = n_va + n_vb + n_vc - 5
    if around < 1:
        raise OclgiError(f"n_va + n_vb + n_vc - 5 must be at least 1, got {around}")
    return (n_zones * r_max * l_max * phi_total**2 * area_ratio
            / ((1 - r_max) * math.pi * around * area * n_rays))
