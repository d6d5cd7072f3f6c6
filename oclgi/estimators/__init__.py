"""Density estimators. Each accumulates fixed-point sums batch by batch and
resolves them to irradiance at the query points (see base.py).

    detp               DETP, plain (the oracle for the accelerated variants)
    detp_disc_index    DETP with a BVH over the discs, segments streamed through it
    detp_ray_map       DETP with a BVH over each batch's segments, queried per disc
    detp_sphere_cache  DETP with a cache of nested spheres along a Hilbert order
    impact             Impact Count with vertex averaging and linear interpolation
    photon_map         Photon Maps: the k nearest impacts over pi r_k^2 (Jensen 1995)
"""

from ..params import METHODS
from .detp import Detp
from .detp_disc_index import DetpDiscIndex
from .detp_ray_map import DetpRayMap
from .detp_sphere_cache import DetpSphereCache
from .impact_count import ImpactCount
from .photon_map import PhotonMap

ESTIMATORS = {
    "detp": Detp,
    "detp_disc_index": DetpDiscIndex,
    "detp_ray_map": DetpRayMap,
    "detp_sphere_cache": DetpSphereCache,
    "impact": ImpactCount,
    "photon_map": PhotonMap,
}
assert tuple(ESTIMATORS) == METHODS, "oclgi/params.py's METHODS must list every estimator"
