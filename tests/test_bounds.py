"""oclgi.study.bounds: the variance bounds of DESIGN.md section 3 ("Efficiency").

The order-statistics factor sigma^2_n(k) = sup_x g_k(x), g_k(x) =
P_k (1 - P_k) / (x (1 - x)) with P_k(x) = I_x(k, n+1-k) = P(Bin(n, x) >= k),
is checked against what can be proved about it:

- k = 1: I_x(1, n) = 1 - (1 - x)^n, so with y = 1 - x
  g_1 = (1 - y^n) y^n / (x y) = y^(n-1) (1 + y + ... + y^(n-1)),
  increasing in y: the sup is its limit n at x -> 0 (and k = n mirrors it).
- symmetry: I_x(a, b) = 1 - I_{1-x}(b, a) gives g_k(x) = g_{n+1-k}(1 - x).
- sigma^2_n(k) <= n: for a Bernoulli(x) parent, g_k(x) is
  Var(k-th largest) / Var(X), and sum_k Var(X_(k)) <= n Var(X) (the order
  statistics sum to the sample sum, their squares to the sum of squares;
  Cauchy-Schwarz on their means).
- a monotone lemma: if P >= P' pointwise (both increasing from 0 to 1) and
  the sup of g' is reached at x* <= 1/2, there is x' <= x* with
  P(x') = P'(x*), where x'(1 - x') <= x*(1 - x*), so sup g >= sup g'. Since
  P_k >= P_{k+1} and P(Bin(n+1, x) >= k) >= P(Bin(n, x) >= k), sigma^2
  decreases in k towards the middle and increases in n, wherever the
  maximiser lies at or below 1/2 (checked too).
"""

import math

import numpy as np
import pytest
from scipy.special import betainc

from oclgi.study import bounds
from oclgi.errors import OclgiError


@pytest.mark.parametrize("n", [1, 2, 3, 10, 1000, 10**6, 10**9])
def test_k1_closed_form(n):
    assert bounds.order_statistic_factor(n, 1) == pytest.approx(n, rel=1e-12)
    assert bounds.order_statistic_factor(n, n if n <= 1000 else 1) == pytest.approx(n, rel=1e-12)
    # the integrand itself against the geometric sum (y^(n-1) (1 - y^n) / (1 - y))
    if n <= 1000:
        x = np.array([1e-6, 0.01, 0.3, 0.5, 0.9])
        y = 1 - x
        closed = y ** (n - 1) * (1 - y**n) / x
        np.testing.assert_allclose(bounds.order_statistic_integrand(x, n, 1), closed, rtol=1e-10)
        if n > 1:  # a sup, not attained (n = 1: g = 1 everywhere)
            assert np.all(bounds.order_statistic_integrand(x, n, 1) < n)


@pytest.mark.parametrize("n,k", [(5, 2), (10, 3), (50, 7), (1000, 50), (10**6, 50)])
def test_symmetry(n, k):
    s, x = bounds.order_statistic_factor(n, k, return_argmax=True)
    s2, x2 = bounds.order_statistic_factor(n, n + 1 - k, return_argmax=True)
    assert s2 == pytest.approx(s, rel=1e-9) and 1 - x2 == pytest.approx(x, rel=1e-4, abs=1e-12)
    xs = np.array([0.01, 0.2, 0.5, 0.77])
    np.testing.assert_allclose(bounds.order_statistic_integrand(xs, n, k),
                               bounds.order_statistic_integrand(1 - xs, n, n + 1 - k), rtol=1e-9)


@pytest.mark.parametrize("n,k", [(2, 1), (3, 2), (7, 2), (20, 5), (20, 10), (100, 3), (100, 50), (500, 20)])
def test_against_a_brute_force_sup(n, k):
    """A fine grid in x (linear, plus log-spaced near both ends) never beats
    the maximiser, and comes within its resolution of it."""
    x = np.concatenate([np.linspace(1e-7, 1 - 1e-7, 200_001), np.logspace(-12, -1, 20_001)])
    x = np.concatenate([x, 1 - x[-20_001:]])
    p = betainc(k, n + 1 - k, x)
    g = p * (1 - p) / (x * (1 - x))
    s = bounds.order_statistic_factor(n, k)
    assert np.nanmax(g) <= s * (1 + 1e-9) and np.nanmax(g) >= s * (1 - 1e-5)


def test_at_most_n_and_the_median():
    n = 30
    assert np.all(np.array([bounds.order_statistic_factor(n, k) for k in range(1, n + 1)]) <= n * (1 + 1e-12))
    # Bernoulli parent: sum_k g_k(x) <= n at every x (Cauchy-Schwarz)
    for x in (0.01, 0.3, 0.5, 0.9):
        assert sum(bounds.order_statistic_integrand(x, n, k) for k in range(1, n + 1)) <= n * (1 + 1e-12)
    # odd n: the median's g at 1/2 is exactly (1/4) / (1/4) = 1, and 1 is its sup
    assert bounds.order_statistic_factor(31, 16) == pytest.approx(1.0, rel=1e-9)


def test_monotone_in_k_towards_the_middle():
    n = 41
    s, x = zip(*(bounds.order_statistic_factor(n, k, return_argmax=True) for k in range(1, (n + 1) // 2 + 1)))
    assert all(xk <= 0.5 + 1e-9 for xk in x)  # the lemma's condition
    assert all(b <= a * (1 + 1e-9) for a, b in zip(s, s[1:]))


@pytest.mark.parametrize("k", [2, 5, 20])
def test_monotone_in_n(k):
    s, x = zip(*(bounds.order_statistic_factor(n, k, return_argmax=True)
                 for n in [2 * k, 2 * k + 1, 3 * k, 10 * k, 100 * k, 10**4 * k]))
    assert all(xn <= 0.5 + 1e-9 for xn in x)
    assert all(b >= a * (1 - 1e-9) for a, b in zip(s, s[1:]))


def test_bound_values():
    # DETP: R / ((1 - R) pi^2 d^2) L Phi^2 / n
    assert bounds.detp_bound(0.5, 1.0, 1.0, 1.0, 1) == pytest.approx(1 / math.pi**2)
    assert bounds.detp_bound(0.5, 2.0, 3.0, 0.5, 10) == pytest.approx(2 * 9 * 4 / (math.pi**2 * 10))
    assert bounds.detp_bound(0.0, 1.0, 1.0, 1.0, 1) == 0.0
    # Photon Maps with k = 1: sigma^2 = n, so R / ((1 - R) pi A) L Phi^2
    assert bounds.photon_map_bound(0.5, 1.0, 1.0, 1.0, 10, k=1) == pytest.approx(1 / math.pi)
    n, k = 10**5, 50
    assert bounds.photon_map_bound(0.75, 1.0, 2.0, 4.0, n, k) == pytest.approx(
        bounds.order_statistic_factor(n, k) * 3 / (math.pi * 4) * 4 / n)
    # Impact Count: N R L Phi^2 K / ((1 - R) pi (na + nb + nc - 5) A n)
    assert bounds.impact_count_bound(0.5, 1.0, 1.0, 1.0, 1, n_zones=2, area_ratio=1.0,
                                     n_va=6, n_vb=6, n_vc=6) == pytest.approx(2 / (13 * math.pi))
    # monotone in what they should be: more rays, less variance; brighter, more
    assert bounds.detp_bound(0.5, 1, 1, 1, 200) == pytest.approx(bounds.detp_bound(0.5, 1, 1, 1, 100) / 2)
    assert bounds.detp_bound(0.6, 1, 1, 1, 1) > bounds.detp_bound(0.5, 1, 1, 1, 1)


@pytest.mark.parametrize("call", [
    lambda: bounds.order_statistic_factor(10, 0),
    lambda: bounds.order_statistic_factor(10, 11),
    lambda: bounds.order_statistic_factor(10.0, 2),
    lambda: bounds.detp_bound(1.0, 1, 1, 1, 1),
    lambda: bounds.detp_bound(0.5, 1, 1, 0.0, 1),
    lambda: bounds.photon_map_bound(0.5, 1, 1, -1.0, 10, 2),
    lambda: bounds.impact_count_bound(0.5, 1, 1, 1, 1, n_zones=1, area_ratio=0.5, n_va=6, n_vb=6, n_vc=6),
    lambda: bounds.impact_count_bound(0.5, 1, 1, 1, 1, n_zones=1, area_ratio=1, n_va=1, n_vb=1, n_vc=1),
])
def test_bad_input(call):
    with pytest.raises(OclgiError):
        call()
