"""The options of DETP's disc radius (``radius_mode``, ``adaptive_k``,
``pilot_photons``, ``radius_min``, ``radii``; oclgi/estimators/adaptive_radius.py
has what they mean), checked before any work: one error line each.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import OclgiError

RADIUS_MODES = ("fixed", "adaptive")
# The defaults, as DetpEstimator's signature gives them (the engine reads
# them to trace the pilot before the estimator is built).
DEFAULTS = {"radius_mode": "fixed", "adaptive_k": 16, "pilot_photons": 32768, "radius_min": 0.25}


def check(radius_mode, adaptive_k, pilot_photons, radius_min) -> None:
    """One error line for a bad option, before any work."""
    from ..params import integral

    if radius_mode not in RADIUS_MODES:
        raise OclgiError(f"radius_mode must be one of {', '.join(map(repr, RADIUS_MODES))}, got {radius_mode!r}")
    k = integral(adaptive_k)
    if isinstance(adaptive_k, bool) or k is None or not 2 <= k <= 256:
        raise OclgiError(f"adaptive_k must be an integer in 2..256, got {adaptive_k!r}")
    n = integral(pilot_photons)
    if isinstance(pilot_photons, bool) or n is None or not 1024 <= n <= 1 << 22:
        raise OclgiError(f"pilot_photons must be an integer in 1024..4194304, got {pilot_photons!r}")
    if not 0.0 < _real(radius_min) <= 1.0:
        raise OclgiError(f"radius_min must be a number in (0, 1], got {radius_min!r}")


def given_radii(radii, radius_mode: str, n: int):
    """``radii`` as (n,) float64, checked; None when not given."""
    if radii is None:
        return None
    if radius_mode != "adaptive":
        raise OclgiError("radii are given with radius_mode 'adaptive' only")
    try:
        r = np.array(radii, np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise OclgiError(f"radii must be {n} positive numbers, got {type(radii).__name__}") from None
    if len(r) != n or not (np.isfinite(r) & (r > 0)).all():
        raise OclgiError(f"radii must be {n} positive finite numbers (one per point), got {len(r)}"
                         + ("" if len(r) != n else " with some not positive or not finite"))
    return r


def consistent_span(consistent, span):
    """Surface-consistent counting's span in radii, or None when it is off; one error line for a bad value."""
    if not isinstance(consistent, (bool, np.bool_)):
        raise OclgiError(f"consistent must be true or false, got {consistent!r}")
    f = _real(span)
    if not 0.0 < f <= 100.0:
        raise OclgiError(f"consistent_span must be a number of radii in (0, 100], got {span!r}")
    return f if consistent else None


def _real(value) -> float:
    """``value`` as a float; NaN (refused by every range) for a bool or what is not a number."""
    if isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan
