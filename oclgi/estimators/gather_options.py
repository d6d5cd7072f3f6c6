"""The options of DETP's final gathering (oclgi/estimators/final_gather.py,
irradiance_cache.py) checked; apart, so that the DETP base class can check them without importing
the estimator built on it."""

from __future__ import annotations

from ..errors import OclgiError
from ..params import integral

MAX_RAYS = 65536
MAX_GATHER_SEED = 1 << 31  # the Philox counter's block is 2 gather_seed (+1): a uint
MAX_SPACING = 64  # pixels between an irradiance cache's records (irradiance_cache.py)


def check(gather, gather_seed) -> int:
    """The number of gather rays per point (0: none); one error line for a bad value."""
    n, seed = integral(gather), integral(gather_seed)
    if n is None or not 0 <= n <= MAX_RAYS:
        raise OclgiError(f"gather must be an integer from 0 (no final gathering) to {MAX_RAYS} rays per point, "
                         f"got {gather!r}")
    if seed is None or not 0 <= seed < MAX_GATHER_SEED:
        raise OclgiError(f"gather_seed must be an integer from 0 to 2^31 - 1, got {gather_seed!r}")
    return n


def spacing(gather_spacing) -> int:
    """The pixels between gathered points (1: every point); one error line for a bad value."""
    s = integral(gather_spacing)
    if s is None or not 1 <= s <= MAX_SPACING:
        raise OclgiError(f"gather_spacing must be an integer from 1 (gather at every point) to {MAX_SPACING} "
                         f"pixels, got {gather_spacing!r}")
    return s


def requested_rays(options: dict, samples: int = 1) -> float:
    """The gather rays per point that ``options`` ask for (0: none), for a
    memory check made before the estimator exists; a value ``check`` would
    refuse counts 0 here (the estimator refuses it with its reason). An
    irradiance cache (``gather_spacing`` s) gathers at one pixel in s^2 of
    one of an image's ``samples`` stacked samples: N / (s^2 samples) a
    point on average (the points it gathers at besides are counted when
    it is built, irradiance_cache.py)."""
    n = integral(options.get("gather", 0))
    if n is None or not 0 < n <= MAX_RAYS:
        return 0
    s = integral(options.get("gather_spacing", 1))
    return n / (s * s * max(int(samples), 1)) if s is not None and 1 < s <= MAX_SPACING else n
