"""Density estimators. Each accumulates fixed-point sums batch by batch and
resolves them to irradiance at the query points (see base.py).

    detp               DETP, plain (the oracle for the accelerated variants)
    detp_disc_index    DETP with a BVH over the discs, segments streamed through it
    detp_ray_map       DETP with a BVH over each batch's segments, queried per disc
    detp_sphere_cache  DETP with a cache of nested spheres along a Hilbert order
    impact             Impact Count with vertex averaging and linear interpolation
    photon_map         Photon Maps: the k nearest impacts over pi r_k^2 (Jensen 1995)
    ray_map_knn        Ray Maps' k nearest segments (Havran et al. 2005): the k nearest
                       tangent-plane crossings (or distances to the rays or lines) over
                       pi r_k^2, as Photon Maps with segments
"""

import functools

from .. import params
from ..errors import OclgiError
from ..params import METHODS
from .detp import Detp
from .detp_disc_index import DetpDiscIndex
from .detp_ray_map import DetpRayMap
from .detp_sphere_cache import DetpSphereCache
from .impact_count import ImpactCount
from .photon_map import PhotonMap
from .ray_map_knn import RayMapKnn

ESTIMATORS = {
    "detp": Detp,
    "detp_disc_index": DetpDiscIndex,
    "detp_ray_map": DetpRayMap,
    "detp_sphere_cache": DetpSphereCache,
    "impact": ImpactCount,
    "photon_map": PhotonMap,
    "ray_map_knn": RayMapKnn,
}
assert tuple(ESTIMATORS) == METHODS, "oclgi/params.py's METHODS must list every estimator"


@functools.lru_cache(maxsize=None)
def option_names(method_name: str) -> frozenset:
    """The options of a method: the keyword parameters of its estimator's
    constructors other than the run parameters and what the engine passes.
    (Sessions build estimators every frame: inspected once per method.)"""
    import inspect

    names = set()
    for klass in ESTIMATORS[method_name].__mro__:
        init = klass.__dict__.get("__init__")
        if init is not None:
            names |= {p.name for p in inspect.signature(init).parameters.values()
                      if p.kind is p.KEYWORD_ONLY or p.kind is p.POSITIONAL_OR_KEYWORD}
    return frozenset(names - params.ENGINE_ARGS - set(params.RUN_KEYS))


def check_options(method_name: str, given: dict) -> dict:
    """The method's own options, their names checked (each estimator checks
    its values when it is built, before any photon is traced)."""
    method_name = params.method(method_name)
    for key in given:
        params.not_a_parameter(key)
    unknown = set(given) - option_names(method_name)
    if unknown:
        takes = ", ".join(sorted(option_names(method_name))) or "none"
        raise OclgiError(f"method {method_name!r} takes no option(s) {sorted(unknown)} (its options: {takes})")
    return dict(given)
