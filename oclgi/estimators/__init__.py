"""Density estimators. Each accumulates fixed-point sums batch by batch and
resolves them to irradiance at the query points (see base.py).

    detp             DETP, plain (the oracle for the accelerated variants)
    detp_disc_index  DETP with a BVH over the discs, segments streamed through it
    detp_ray_map     DETP with a BVH over each batch's segments, queried per disc
    impact           Impact Count with vertex averaging and linear interpolation
"""

from .detp import Detp
from .detp_disc_index import DetpDiscIndex
from .detp_ray_map import DetpRayMap
from .impact_count import ImpactCount

ESTIMATORS = {
    "detp": Detp,
    "detp_disc_index": DetpDiscIndex,
    "detp_ray_map": DetpRayMap,
    "impact": ImpactCount,
}
METHODS = tuple(ESTIMATORS)
