"""Density estimators. Each accumulates fixed-point sums batch by batch and
resolves them to irradiance at the query points (see base.py).

    detp    DETP, plain (the oracle for the accelerated variants)
    impact  Impact Count with vertex averaging and linear interpolation
"""

from .detp import Detp
from .impact_count import ImpactCount

ESTIMATORS = {"detp": Detp, "impact": ImpactCount}
METHODS = tuple(ESTIMATORS)
