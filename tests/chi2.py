"""A chi-square test of sampled directions against their density (the test
of Mitsuba 3's ``chi2.py``, written for oclgi's device BSDFs).

The sphere of directions is cut into equal-area cells, ``n_z`` bands of
cos(theta) by ``n_phi`` sectors (dz dphi is the solid angle). A sampler's
directions are counted per cell; a cell's expected count is the pdf
integrated over it (a midpoint rule, refined where it has not converged)
times the number of samples drawn, absorbed ones included (the pdf
integrates to the fraction that is not absorbed). Cells expecting fewer
than 5 samples are pooled into one, as Mitsuba does; the p-value comes
from the chi-square distribution, and a test passes when it is above a
significance level corrected for the number of tests run (Sidak).
"""

from __future__ import annotations

import numpy as np
from scipy import stats


def cell_directions(cells: np.ndarray, n_z: int, n_phi: int, sub: int) -> np.ndarray:
    """(len(cells) * sub^2, 3) unit directions: the midpoints of the given
    cells' sub-cells, cell by cell (cell = iz * n_phi + iphi)."""
    cells = np.asarray(cells)
    k = (np.arange(sub) + 0.5) / sub
    iz, ip = np.divmod(cells, n_phi)
    z = -1.0 + 2.0 * (iz[:, None, None] + k[None, :, None]) / n_z
    phi = 2.0 * np.pi * (ip[:, None, None] + k[None, None, :]) / n_phi
    z, phi = np.broadcast_arrays(z, phi)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1).reshape(-1, 3)


def expected_counts(pdf, n_z: int, n_phi: int, n_samples: int, sub: int = 8, max_sub: int = 128) -> np.ndarray:
    """Each cell's expected count: ``pdf(directions)`` integrated over the
    cell by the midpoint rule, the number of sub-cells doubled per axis
    where that changes the count by more than 0.05 (a lobe's sharp edge,
    a peak near the horizon), up to ``max_sub`` x ``max_sub``."""
    area = 4.0 * np.pi / (n_z * n_phi)
    cells = np.arange(n_z * n_phi)

    def integrate(c, k):
        return pdf(cell_directions(c, n_z, n_phi, k)).reshape(len(c), k * k).mean(axis=1) * area * n_samples

    counts = integrate(cells, sub)
    active = cells
    while sub < max_sub and len(active):
        sub *= 2
        finer = integrate(active, sub)
        changed = np.abs(finer - counts[active]) > 0.05
        counts[active] = finer
        active = active[changed]
    return counts


def cell_of(d: np.ndarray, n_z: int, n_phi: int) -> np.ndarray:
    z = np.clip(d[:, 2], -1.0, 1.0)
    phi = np.arctan2(d[:, 1], d[:, 0]) % (2.0 * np.pi)
    iz = np.minimum((0.5 * (z + 1.0) * n_z).astype(np.int64), n_z - 1)
    ip = np.minimum((phi / (2.0 * np.pi) * n_phi).astype(np.int64), n_phi - 1)
    return iz * n_phi + ip


def chi2_pvalue(observed: np.ndarray, expected: np.ndarray, min_expected: float = 5.0):
    """(p-value, degrees of freedom) of the counts against the expectation,
    cells under ``min_expected`` pooled. An observation in a cell expected
    empty is a failure (p = 0)."""
    observed = np.asarray(observed, np.float64)
    if (observed[expected <= 0] > 0).any():
        return 0.0, 0
    small = expected < min_expected
    obs = list(observed[~small])
    exp = list(expected[~small])
    if small.any() and expected[small].sum() > 0:
        obs.append(observed[small].sum())
        exp.append(expected[small].sum())
    obs, exp = np.array(obs), np.array(exp)
    # the sampler's total may be below the pdf's (absorbed samples): compare
    # only within the cells, with the missing mass a cell of its own
    dof = len(obs) - 1
    stat = float(((obs - exp) ** 2 / exp).sum())
    return float(stats.chi2.sf(stat, dof)), dof


def sidak(alpha: float, n_tests: int) -> float:
    return 1.0 - (1.0 - alpha) ** (1.0 / n_tests)
