"""Photometric units: lux, lumens and candela for RGB radiometric values.

oclgi's RGB channels are radiometric (watts, W/m^2, W/sr per channel). For
lighting design they convert with one convention, stated here once: the
channels are linear Rec. 709 (sRGB) primaries, luminance is
Y = 0.2126 R + 0.7152 G + 0.0722 B, and one watt of Y is 683 lumens (the
luminous efficacy that defines the candela, at 555 nm). So equal RGB of
1 W/sr is 683 cd, an irradiance of equal RGB 1 W/m^2 is 683 lux, and a
white light of P lumens emits P / 683 W in each channel.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import OclgiError

LUMENS_PER_WATT = 683.0
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 Y weights; they sum to 1


def luminance(rgb) -> np.ndarray:
    """Y of RGB values (..., 3)."""
    return np.asarray(rgb, np.float64) @ LUMINANCE


def illuminance_lux(irradiance) -> np.ndarray:
    """Illuminance (lux) of RGB irradiance (..., 3) in W/m^2 per channel."""
    return LUMENS_PER_WATT * luminance(irradiance)


def intensity_from_candela(candela: float, colour=(1.0, 1.0, 1.0)) -> tuple:
    """A point light's RGB intensity (W/sr) for ``candela`` of light of
    ``colour`` (its luminance scaled to match)."""
    return _scaled(colour, candela / LUMENS_PER_WATT, "candela")


def irradiance_from_lux(lux: float, colour=(1.0, 1.0, 1.0)) -> tuple:
    """A sun's RGB irradiance (W/m^2 on a plane perpendicular to it) for
    ``lux`` of light of ``colour`` (its luminance scaled to match)."""
    return _scaled(colour, lux / LUMENS_PER_WATT, "lux")


def emission_from_lumens(lumens: float, area: float, colour=(1.0, 1.0, 1.0)) -> tuple:
    """The RGB radiance (W/m^2/sr) of a one-sided Lambertian emitter of
    ``area`` that sends out ``lumens`` of light of ``colour``: the flux of
    radiance L over a one-sided area A is pi A L."""
    if not area > 0:
        raise OclgiError(f"lumens: the emitting surface has no area ({area})")
    return _scaled(colour, lumens / (LUMENS_PER_WATT * math.pi * area), "lumens")


def _scaled(colour, y: float, what: str) -> tuple:
    c = np.asarray(colour, np.float64)
    lum = float(luminance(c))
    if not lum > 0:
        raise OclgiError(f"{what}: the light's colour {tuple(c)} has no luminance")
    return tuple(float(v) for v in c * (y / lum))
