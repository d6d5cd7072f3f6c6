"""Lights: the kinds, their parameters, power, device records and Mitsuba form.

The device samples every kind in ``kernels/light.h``; this module is the
host's one place for them. Area lights are emissive materials on triangles
(``Material.emission``, a one-sided Lambertian radiance); the other kinds
are objects of their own, read from the scene file's tables
(oclgi/scene/light_tables.py):

==============  ============================================================
table           parameters (defaults)
==============  ============================================================
[[point_light]] ``position``; ``intensity`` (W/sr) or ``candela`` (with
                ``colour``, default white). Uniform over the sphere: power
                4 pi I.
[[spot_light]]  ``position``; ``direction`` (the axis it points along);
                ``intensity`` (W/sr on the axis) or ``candela`` (+
                ``colour``); ``cone_angle`` (half-angle, degrees, 30);
                ``cone_delta`` (degrees, 5): full intensity within
                cone_angle - cone_delta of the axis, then pbrt-v4's
                smoothstep in cos(theta) down to 0 at cone_angle. Power
                2 pi I ((1 - cos_start) + (cos_start - cos_end) / 2), exact
                for that profile (the smoothstep integrates to a half).
[[sun]]         ``direction`` (the direction the light travels, from the
                sun into the scene); ``irradiance`` (W/m^2 on a plane
                perpendicular to it) or ``lux`` (+ ``colour``). Photons
                start on a disc of the scene's bounding-sphere radius R
                outside that sphere: power E pi R^2.
[sky]           ``radiance`` (W/m^2/sr, uniform); ``hemisphere`` (true):
                light comes only from the directions above the horizon of
                ``up`` ([0, 1, 0]), false: from every direction. Photons
                travel along a direction uniform over the (half-)sphere from
                a disc of radius R perpendicular to it, outside the bounding
                sphere: power L pi R^2 times the solid angle (2 pi or 4 pi).
                An unoccluded plane facing ``up`` receives pi L either way.
IES profiles    ``ies = "file.ies"`` in a [[point_light]] or [[spot_light]]
                (relative to the scene file; oclgi/scene/ies.py reads it):
                the file's candela distribution (type C) instead of a
                uniform intensity; ``candela`` (the peak, cd) or
                ``lumens`` (the light's total flux) rescales it, ``colour``
                tints it (default white). Orientation: ``direction`` (where
                the nadir, gamma = 0, points; [0, -1, 0] for a point light,
                the axis for a spot) and ``c0`` (the direction of the C = 0
                half-plane, made perpendicular to it; default world x, or z
                when the nadir is along x), or ``matrix`` (3 rows of 3, a
                rotation whose columns are the luminaire's x = C 0, y = C 90
                and z = zenith axes in the scene; points only). A spot
                multiplies the profile by its cone's smoothstep. Power: the
                profile's flux (ies.tables), exact for its bins.
[sky] with map  ``map``: an equirectangular image (EXR, HDR, ... through
                OpenImageIO; relative to the scene file) of radiance
                (W/m^2/sr), Mitsuba's orientation (row 0 the zenith +y,
                column u looking along (sin phi, ., -cos phi) at phi =
                2 pi u); ``scale`` (1) multiplies it. Importance-sampled by
                luminance x solid angle of its texels (piecewise constant):
                power pi R^2 x the map's integral of radiance.
==============  ============================================================

Point and spot lights take an optional ``name`` (a string: what ``oclgi
animate --light`` moves them by) and an optional ``path``, the keyframes
of its animation (rows ``[x, y, z]``; a spot's may be ``[x, y, z, dx, dy,
dz]``, position and axis), which ``animate --light NAME`` and
``oclgi.LightSession`` take when no other path is given. Unknown keys are errors, as everywhere in
a scene file. The sun and sky
cover the scene's geometry as loaded (its bounding sphere): a movable
object moved outside that sphere is not lit by them.

Power and phi_max. Emitters are chosen in proportion to their (exact)
power; a photon from emitter i carries at most bound_i / p_i watts (times
the photon count), where bound_i is power_i for the kinds whose photons all
carry the same, and more for the two whose photons vary: the spot (photons
leave uniformly over the cone, weighted by its profile: bound = power x
the cone's solid angle / the profile's integral) and the environment map
(texels chosen by luminance, weighted by their colour); an IES spot's
photons sample the profile's bins that reach into the cone and carry its
smoothstep (bound = the flux of those bins, unmasked). The largest of
these is phi_max (oclgi/scene/compiled.py), the device's unit, so no
photon carries more than 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..accel.boxes import box_corners
from ..cl.constants import (EMITTER_ENVMAP, EMITTER_IES, EMITTER_POINT, EMITTER_SKY, EMITTER_SPOT, EMITTER_SUN,
                            EMITTER_TRIANGLE)
from ..errors import OclgiError
from ..params import MAX_LENGTH as MAX_COORDINATE  # as for vertices (oclgi/scene/scene.py)
from ..photometry import LUMINANCE
from . import values
from .ies import cdf_tables

# The scene file's tables, and whether each is a list ([[name]]) or one table ([name]).
TABLES = {"point_light": True, "spot_light": True, "sun": True, "sky": False}
# An environment map's largest size (texels): its tables are 4 floats a texel on the device.
ENVMAP_MAX_TEXELS = 1 << 24
SPOT_CONE_ANGLE = 30.0  # degrees, pbrt-v4's default coneangle
SPOT_CONE_DELTA = 5.0  # degrees, pbrt-v4's default conedelta
SKY_UP = (0.0, 1.0, 0.0)
# Outside the bounding sphere by this fraction of its radius: the sun's and
# sky's discs stay clear of the geometry after float32 rounding.
SPHERE_MARGIN = 1e-3


def _rgb(v) -> np.ndarray:
    return np.asarray(v, dtype=np.float64)


def _floats(v):
    """v as a float64 array, or None when it is not numbers (a light made in Python)."""
    try:
        a = np.asarray(v)
        return a.astype(np.float64) if a.dtype.kind in "iuf" else None
    except (TypeError, ValueError):
        return None


def _unit(v, where: str) -> np.ndarray:
    d = _floats(v)
    n = float(np.linalg.norm(d)) if d is not None and d.shape == (3,) and np.isfinite(d).all() else 0.0
    if not n > 0:
        raise OclgiError(f"{where}: expected a non-zero direction of 3 finite numbers, got {v!r}")
    return d / n


def _check_radiant(v, where: str):
    from .. import params

    try:
        a = np.asarray(v, dtype=object).ravel()
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (3,):
        raise OclgiError(f"{where}: expected 3 numbers, got {v!r}")
    for x in a:
        params.float32_real(x, where, 0.0)


def _check_point(v, where: str):
    a = _floats(v)
    if a is None or a.shape != (3,) or not np.isfinite(a).all() or np.abs(a).max() > MAX_COORDINATE:
        raise OclgiError(f"{where}: expected 3 finite numbers within {MAX_COORDINATE:.0e}, got {v!r}")


@dataclass
class PointLight:
    """A point light, uniform over the sphere.

    ==========  =========================================
    position    3 numbers, world space
    intensity   RGB radiant intensity, W/sr per channel
    name        optional, what a light animation calls it
    path        optional keyframes of a light animation: rows x, y, z
    ==========  =========================================
    """

    position: tuple[float, float, float]
    intensity: tuple[float, float, float]  # W/sr per channel
    name: str | None = None
    path: tuple | None = field(default=None, repr=False)  # keyframes (rows of 3), oclgi animate --light

    table = "point_light"

    @property
    def power(self) -> np.ndarray:
        return 4.0 * math.pi * _rgb(self.intensity)

    def validate(self, where: str):
        if not (np.isfinite(self.position).all() and np.isfinite(self.intensity).all()) or min(self.intensity) < 0:
            raise OclgiError(f"point light at {self.position}: bad position or intensity")

    def record(self, sphere) -> dict:
        return {"kind": EMITTER_POINT, "p": self.position}

    def to_mitsuba(self, mi, sphere) -> dict:
        return {"type": "point", "position": [float(c) for c in self.position],
                "intensity": {"type": "rgb", "value": [float(c) for c in self.intensity]}}


@dataclass
class SpotLight:
    """A spot light with pbrt-v4's profile (smoothstep in cos theta).

    ===========  ==============================================================
    position     3 numbers, world space
    direction    the cone's axis (normalised here)
    intensity    RGB radiant intensity on the axis, W/sr per channel
    cone_angle   half-angle of the cone, degrees, in (0, 180]
    cone_delta   width of the falloff band inside the cone, degrees, in
                 [0, cone_angle]
    name         optional, what a light animation calls it
    path         optional keyframes of a light animation: rows x, y, z or
                 x, y, z, dx, dy, dz (position and axis)
    ===========  ==============================================================
    """

    position: tuple[float, float, float]
    direction: tuple[float, float, float]
    intensity: tuple[float, float, float]
    cone_angle: float = SPOT_CONE_ANGLE
    cone_delta: float = SPOT_CONE_DELTA
    name: str | None = None
    path: tuple | None = field(default=None, repr=False)  # keyframes (rows of 3 or 6), oclgi animate --light

    table = "spot_light"

    @property
    def cos_total(self) -> float:
        return math.cos(math.radians(self.cone_angle))

    @property
    def cos_start(self) -> float:
        return math.cos(math.radians(self.cone_angle - self.cone_delta))

    def profile(self, cos_theta):
        """The fraction of the axis intensity emitted at cos_theta (pbrt-v4's SpotLight::I)."""
        c = np.asarray(cos_theta, np.float64)
        lo, hi = self.cos_total, self.cos_start
        if hi == lo:
            return (c >= lo).astype(np.float64)
        t = np.clip((c - lo) / (hi - lo), 0.0, 1.0)
        return t * t * (3 - 2 * t)

    @property
    def solid_angle_weight(self) -> float:
        """The integral of the profile over the sphere (sr): the smoothstep
        over [cos_total, cos_start] integrates to half the band's width."""
        lo, hi = self.cos_total, self.cos_start
        return 2.0 * math.pi * ((1.0 - hi) + (hi - lo) / 2.0)

    @property
    def power(self) -> np.ndarray:
        return self.solid_angle_weight * _rgb(self.intensity)

    def validate(self, where: str):
        _check_point(self.position, where + ".position")
        _unit(self.direction, where + ".direction")
        _check_radiant(self.intensity, where + ".intensity")
        a, d = self.cone_angle, self.cone_delta
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0 < a <= 180:
            raise OclgiError(f"{where}.cone_angle: expected a half-angle in (0, 180] degrees, got {a!r}")
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not 0 <= d <= a:
            raise OclgiError(f"{where}.cone_delta: expected degrees from 0 to cone_angle ({a}), got {d!r}")

    @property
    def peak(self) -> float:
        """Photons leave uniformly over the cone: the largest carries the
        cone's solid angle times I, the mean the power."""
        return 2.0 * math.pi * (1.0 - self.cos_total) / self.solid_angle_weight

    def record(self, sphere) -> dict:
        return {"kind": EMITTER_SPOT, "p": self.position, "e1": _unit(self.direction, "spot_light.direction"),
                "a": self.cos_total, "b": self.cos_start}

    def to_mitsuba(self, mi, sphere) -> dict:
        """Mitsuba's ``spot``: the same intensity on the axis and the same
        cone; within the falloff band Mitsuba ramps linearly in the angle,
        oclgi by smoothstep in its cosine (equal with cone_delta = 0)."""
        p = np.asarray(self.position, np.float64)
        d = _unit(self.direction, "spot_light.direction")
        up = [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0]
        return {"type": "spot", "intensity": {"type": "rgb", "value": [float(c) for c in self.intensity]},
                "cutoff_angle": float(self.cone_angle),
                "beam_width": float(self.cone_angle - self.cone_delta),
                "to_world": mi.ScalarTransform4f().look_at(origin=[float(c) for c in p],
                                                          target=[float(c) for c in p + d], up=up)}


@dataclass
class SunLight:
    """A directional light (the sun): parallel rays over the whole scene.

    ===========  ==============================================================
    direction    the direction the light travels (normalised here)
    irradiance   RGB irradiance on a plane perpendicular to it, W/m^2
    ===========  ==============================================================
    """

    direction: tuple[float, float, float]
    irradiance: tuple[float, float, float]

    table = "sun"

    def power_for(self, sphere) -> np.ndarray:
        _, r = sphere
        return math.pi * r * r * _rgb(self.irradiance)

    def validate(self, where: str):
        _unit(self.direction, where + ".direction")
        _check_radiant(self.irradiance, where + ".irradiance")

    def record(self, sphere) -> dict:
        c, r = sphere
        return {"kind": EMITTER_SUN, "p": c, "e1": _unit(self.direction, "sun.direction"), "a": r}

    def to_mitsuba(self, mi, sphere) -> dict:
        return {"type": "directional", "direction": [float(c) for c in _unit(self.direction, "sun.direction")],
                "irradiance": {"type": "rgb", "value": [float(c) for c in self.irradiance]}}


@dataclass
class SkyLight:
    """A uniform sky: radiance from every direction, or from those above the horizon.

    ===========  ==============================================================
    radiance     RGB radiance, W/m^2/sr per channel
    hemisphere   true: only from directions w with w . up > 0; false: all
    up           the sky's zenith (normalised here), for ``hemisphere``
    ===========  ==============================================================
    """

    radiance: tuple[float, float, float]
    hemisphere: bool = True
    up: tuple[float, float, float] = SKY_UP

    table = "sky"

    @property
    def solid_angle(self) -> float:
        return (2.0 if self.hemisphere else 4.0) * math.pi

    def power_for(self, sphere) -> np.ndarray:
        _, r = sphere
        return math.pi * r * r * self.solid_angle * _rgb(self.radiance)

    def validate(self, where: str):
        _check_radiant(self.radiance, where + ".radiance")
        if not isinstance(self.hemisphere, (bool, np.bool_)):
            raise OclgiError(f"{where}.hemisphere: expected true or false, got {self.hemisphere!r}")
        _unit(self.up, where + ".up")

    def record(self, sphere) -> dict:
        c, r = sphere
        return {"kind": EMITTER_SKY, "p": c, "e1": _unit(self.up, "sky.up"), "a": r,
                "b": 1.0 if self.hemisphere else 0.0}

    def to_mitsuba(self, mi, sphere) -> dict:
        """Mitsuba's ``constant`` for the whole sphere; for the hemisphere an
        ``envmap`` bright above its equator and black below, turned so that
        its +y is ``up``. Its rows are bilinearly filtered, so the last row
        above the horizon blends a little (2 / rows of the sky's solid
        angle): 512 rows keep that below 0.4%."""
        rgb = [float(c) for c in self.radiance]
        if not self.hemisphere:
            return {"type": "constant", "radiance": {"type": "rgb", "value": rgb}}
        rows, cols = 512, 8
        img = np.zeros((rows, cols, 3), np.float32)
        img[: rows // 2] = rgb
        up = _unit(self.up, "sky.up")
        other = [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 0.0, 1.0]
        x = np.cross(up, other)
        x /= np.linalg.norm(x)
        z = np.cross(x, up)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2] = x, up, z  # the envmap's y axis onto up
        return {"type": "envmap", "bitmap": mi.Bitmap(img), "to_world": mi.ScalarTransform4f(m.tolist())}


@dataclass(eq=False)
class EnvMapLight:
    """An environment map: radiance from every direction, an equirectangular image.

    ===========  ==============================================================
    radiance     (H, W, 3) RGB radiance, W/m^2/sr, row 0 at the zenith (+y)
                 (kernels/light.h has the directions of its texels)
    name         where it came from (a file name), for messages
    ===========  ==============================================================
    """

    radiance: np.ndarray
    name: str = "map"

    table = "sky"

    def _omega(self) -> np.ndarray:
        """(H,) solid angle of one texel of each row."""
        h, w = self.radiance.shape[:2]
        c = np.cos(np.pi * np.arange(h + 1) / h)
        return 2 * np.pi / w * (c[:-1] - c[1:])

    def power_for(self, sphere) -> np.ndarray:
        _, r = sphere
        lrgb = np.asarray(self.radiance, np.float64)
        return math.pi * r * r * np.einsum("hwc,h->c", lrgb, self._omega())

    def validate(self, where: str):
        a = np.asarray(self.radiance)
        if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1 or a.dtype.kind not in "iuf":
            raise OclgiError(f"{where}.map: expected an (H, W, 3) image of numbers, got {a.dtype} {a.shape}")
        if a.shape[0] * a.shape[1] > ENVMAP_MAX_TEXELS:
            raise OclgiError(f"{where}.map: {a.shape[1]} x {a.shape[0]} texels; at most {ENVMAP_MAX_TEXELS:,}")
        if not np.isfinite(a).all() or (a < 0).any() or (a > values.F32_MAX).any():
            raise OclgiError(f"{where}.map: {self.name}: radiance must be finite, >= 0 and within float32")

    def tables(self):
        """(row CDF (H,), column CDFs (H, W), g (H, W, 3), bound): the
        device's sampling tables (kernels/light.h) and the largest photon
        power times the selection probability, per unit pi R^2."""
        lrgb = np.asarray(self.radiance, np.float64)
        lum = lrgb @ LUMINANCE
        weight = lum * self._omega()[:, None]  # texel probability, unnormalised
        total = float(weight.sum())
        rows, cols = cdf_tables(weight, total)
        ratio = np.divide(lrgb, lum[..., None], out=np.zeros_like(lrgb), where=lum[..., None] > 0)
        m = float(ratio.max())
        return rows, cols, ratio / m, total * m

    def record(self, sphere) -> dict:
        """The record, with its tables (row CDF, column CDFs, g) as one array
        for the emitter CDF buffer, and the photons' bound."""
        c, r = sphere
        h, w = self.radiance.shape[:2]
        rows, cols, g, bound = self.tables()
        return {"kind": EMITTER_ENVMAP, "p": c, "e2": (float(w), float(h), 0.0), "a": r,
                "table": np.concatenate([rows, cols.ravel(), g.ravel()]),
                "bound": np.full(3, math.pi * r * r * bound)}

    def to_mitsuba(self, mi, sphere) -> dict:
        """Mitsuba's ``envmap`` of the same image, in its own orientation
        (which oclgi's follows); Mitsuba filters it bilinearly, oclgi holds
        each texel constant."""
        return {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(self.radiance, dtype=np.float32))}


@dataclass(eq=False)
class IesLight:
    """A point or spot light with an IES profile (oclgi/scene/ies.py): the
    intensity in direction (gamma, C) of the luminaire's frame is the
    profile's candela there times ``scale``, of ``colour``; a spot's cone
    multiplies it by its smoothstep (as SpotLight's).

    ===========  ==============================================================
    position     3 numbers, world space
    profile      the IesProfile (whole circle)
    direction    unit nadir (gamma = 0) in the scene
    c0           unit direction of the C = 0 half-plane, perpendicular to it
                 (C = 90 is c0 x direction: LM-63's counter-clockwise seen
                 from above)
    scale        factor on the profile's candela
    colour       RGB, scaled to luminance 1 (photometry.intensity_from_candela)
    cone_angle   a spot's cone half-angle, degrees; None for a point light
    cone_delta   a spot's falloff band, degrees
    name         optional, as for point and spot lights
    ===========  ==============================================================
    """

    position: tuple[float, float, float]
    profile: object
    direction: tuple[float, float, float] = (0.0, -1.0, 0.0)
    c0: tuple[float, float, float] = (1.0, 0.0, 0.0)
    scale: float = 1.0
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    cone_angle: float | None = None
    cone_delta: float = SPOT_CONE_DELTA
    name: str | None = None
    where: str | None = None  # the scene file's table, for messages

    @property
    def table(self) -> str:
        return "point_light" if self.cone_angle is None else "spot_light"

    @property
    def cone(self) -> tuple[float, float]:
        """(cos of the cone's half-angle, cos of the falloff's start); (-1, -1): no cone."""
        if self.cone_angle is None:
            return -1.0, -1.0
        return math.cos(math.radians(self.cone_angle)), math.cos(math.radians(self.cone_angle - self.cone_delta))

    @property
    def rgb_per_candela(self) -> np.ndarray:
        """RGB W/sr of one candela of the profile (its scale and colour included)."""
        from ..photometry import intensity_from_candela

        return np.asarray(intensity_from_candela(self.scale, self.colour))

    def _tables(self):
        key = (id(self.profile), self.cone)
        if getattr(self, "_cached", (None,))[0] != key:
            from .ies import tables

            self._cached = (key, tables(self.profile, *self.cone))
        return self._cached[1]

    @property
    def flux(self) -> float:
        """Candela x sr (lumens) of the profile as emitted, before ``scale``."""
        return self._tables()[1]

    @property
    def power(self) -> np.ndarray:
        return self.flux * self.rgb_per_candela

    def validate(self, where: str):
        from .ies import IesProfile

        where = self.where or where
        _check_point(self.position, where + ".position")
        d, c = _unit(self.direction, where + ".direction"), _unit(self.c0, where + ".c0")
        if abs(float(d @ c)) > 1e-6:
            raise OclgiError(f"{where}.c0: must be perpendicular to the direction (the nadir), got {self.c0!r}")
        if not isinstance(self.profile, IesProfile):
            raise OclgiError(f"{where}.ies: expected an IesProfile (oclgi.scene.ies), got "
                             f"{type(self.profile).__name__}")
        if isinstance(self.scale, bool) or not isinstance(self.scale, (int, float)) or not self.scale > 0:
            raise OclgiError(f"{where}: the profile's scale must be a number > 0, got {self.scale!r}")
        if self.cone_angle is not None:
            SpotLight(self.position, self.direction, (1.0, 1.0, 1.0), self.cone_angle, self.cone_delta).validate(where)
        _check_radiant(self.power, where + " (its power, W)")
        _check_radiant(self.rgb_per_candela * self.profile.peak, where + " (its peak intensity, W/sr)")

    def record(self, sphere) -> dict:
        table, _, bound = self._tables()
        a, b = self.cone
        return {"kind": EMITTER_IES, "p": self.position, "e1": _unit(self.direction, "ies.direction"),
                "e2": _unit(self.c0, "ies.c0"), "a": a, "b": b, "table": table,
                "bound": bound * self.rgb_per_candela}

    def to_mitsuba(self, mi, sphere):
        """Mitsuba 3 has no IES (goniometric) emitter: the light is left out
        of the Mitsuba scene, with a warning."""
        import warnings

        from ..errors import OclgiWarning

        warnings.warn(f"{self.where or self.table}: Mitsuba 3 has no IES profiles; {self.profile.name} is left "
                      "out of the Mitsuba scene", OclgiWarning, stacklevel=2)
        return None


LIGHT_TYPES = (PointLight, SpotLight, SunLight, SkyLight, EnvMapLight, IesLight)


def bounding_sphere(scene) -> tuple[np.ndarray, float]:
    """(centre, radius) of a sphere around the scene's geometry as loaded,
    a little larger (SPHERE_MARGIN) than the one through its box's corners."""
    lo, hi = scene.bounds()
    centre = 0.5 * (lo + hi)
    return centre, 0.5 * float(np.linalg.norm(hi - lo)) * (1.0 + SPHERE_MARGIN)


def all_lights(scene) -> list:
    """The scene's lights other than its area lights: point lights first, then the rest in order."""
    return [*scene.point_lights, *scene.lights]


def power(light, sphere) -> np.ndarray:
    """RGB watts the light emits (the sun and sky: through their disc, radius of ``sphere``)."""
    return light.power_for(sphere) if hasattr(light, "power_for") else light.power


@dataclass
class EmitterRows:
    """Every emitter of a scene, one row each: area lights (its emissive
    triangles) first, then the other lights (:func:`all_lights`, those
    with power). ``power`` is exact (RGB watts); ``bound`` the largest
    power one photon of the emitter carries, times its selection
    probability (= power for the kinds whose photons all carry the same:
    all but the spot and the environment map). ``table``: the environment
    maps' tables, which ``tri`` of their rows indexes (kernels/light.h)."""

    kind: np.ndarray  # (E,) int32
    tri: np.ndarray  # (E,) int32: the triangle's id, an environment map's or IES profile's table offset, else -1
    p: np.ndarray  # (E, 3)
    e1: np.ndarray  # (E, 3)
    e2: np.ndarray  # (E, 3)
    a: np.ndarray  # (E,)
    b: np.ndarray  # (E,)
    power: np.ndarray  # (E, 3) watts
    bound: np.ndarray  # (E, 3) watts
    table: np.ndarray  # (T,) float64


def emitter_rows(scene) -> EmitterRows:
    """The scene's emitters as the device's records need them (oclgi/scene/compiled.py)."""
    emission = np.array([m.emission for m in scene.materials], dtype=np.float64)
    tri_le = emission[scene.tri_material]
    tri_ids = np.nonzero(tri_le.max(axis=1) > 0)[0]
    v = scene.vertices[scene.faces[tri_ids]]
    areas = scene.triangle_areas()[tri_ids]
    n_tri = len(tri_ids)
    tri_power = math.pi * areas[:, None] * tri_le[tri_ids]
    cols = {"kind": [np.full(n_tri, EMITTER_TRIANGLE, np.int32)], "tri": [tri_ids.astype(np.int32)],
            "p": [v[:, 0]], "e1": [v[:, 1] - v[:, 0]], "e2": [v[:, 2] - v[:, 0]], "a": [np.zeros(n_tri)],
            "b": [np.zeros(n_tri)], "power": [tri_power], "bound": [tri_power]}
    tables, n_table = [], 0
    sphere = bounding_sphere(scene)
    for light in all_lights(scene):
        watts = power(light, sphere)
        if not watts.max() > 0:
            continue
        rec = light.record(sphere)
        tri = -1
        if "table" in rec:
            tri, n_table = n_table, n_table + len(rec["table"])
            tables.append(rec["table"])
        bound = rec.get("bound", watts * getattr(light, "peak", 1.0))
        for key, value in (("kind", np.int32(rec["kind"])), ("tri", np.int32(tri)), ("p", rec["p"]),
                           ("e1", rec.get("e1", (0.0, 0.0, 0.0))), ("e2", rec.get("e2", (0.0, 0.0, 0.0))),
                           ("a", rec.get("a", 0.0)), ("b", rec.get("b", 0.0)), ("power", watts), ("bound", bound)):
            cols[key].append(np.asarray([value]))
    out = {k: np.concatenate(v).astype(np.int32 if k in ("kind", "tri") else np.float64) for k, v in cols.items()}
    return EmitterRows(**out, table=np.concatenate(tables) if tables else np.zeros(0))


def validate(scene) -> None:
    """Each light's parameters, one line naming the bad one."""
    for i, light in enumerate(scene.point_lights):
        light.validate(f"point_light[{i}]")
    counts = {}
    for light in scene.lights:
        if not isinstance(light, LIGHT_TYPES) or isinstance(light, PointLight):
            raise OclgiError(f"{scene.name}: scene.lights holds spot, sun and sky lights "
                             f"(oclgi.scene.lights), got {type(light).__name__}")
        i = counts.get(light.table, 0)
        counts[light.table] = i + 1
        light.validate(light.table if not TABLES[light.table] else f"{light.table}[{i}]")
    if counts.get("sky", 0) > 1:  # a sky and a map, both from the sky's disc: one of them
        raise OclgiError(f"{scene.name}: at most one sky, got {counts['sky']}")


def has_power(scene) -> bool:
    sphere = bounding_sphere(scene)
    return any(power(light, sphere).max() > 0 for light in all_lights(scene))


# -- area lights that light nothing -----------------------------------------------------------------------------

# The check below tests each distinct emitter plane against every vertex;
# past this many vertex tests it stops (the planes left are not reported),
# so that a finely tessellated curved light costs a fraction of a second.
MAX_VERTEX_TESTS = 50_000_000


def escaping_area_lights(scene) -> np.ndarray:
    """Ids of the emissive triangles with no geometry in front of them: the
    open half-space on the normal's side holds no vertex of the scene (as
    loaded), so every photon they emit leaves the scene. The converse holds
    too: geometry in front of a triangle is hit by some of its cosine-
    distributed photons. Triangles are grouped by plane (a quad light is
    one test), and the scene's box rules most planes out first."""
    emission = np.array([m.emission for m in scene.materials], dtype=np.float64)
    ids = np.nonzero(emission[scene.tri_material].max(axis=1) > 0)[0]
    if not len(ids):
        return ids
    n = scene.triangle_normals()[ids]
    v0 = scene.vertices[scene.faces[ids, 0]]
    offset = np.einsum("ij,ij->i", n, v0)
    tol = 1e-6 * max(scene.diagonal, 1e-30)
    lo, hi = scene.bounds()
    box_front = (box_corners(lo, hi) @ n.T - offset).max(axis=0) > tol
    suspects = np.nonzero(~box_front)[0]
    # A box with nothing in front already proves it; the others need the vertices.
    escaping = list(suspects)
    rest = np.nonzero(box_front)[0]
    key = np.round(np.hstack([n[rest], offset[rest, None] / tol]), 6)
    planes, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    first = np.zeros(len(planes), np.int64)
    first[inverse[::-1]] = rest[::-1]  # a representative triangle per plane
    verts = scene.vertices
    for k in range(min(len(planes), max(1, MAX_VERTEX_TESTS // max(len(verts), 1)))):
        j = first[k]
        if not ((verts @ n[j]) - offset[j] > tol).any():
            escaping.extend(rest[inverse == k])
    return np.sort(ids[np.asarray(escaping, dtype=np.int64)])


def mitsuba_emitters(mi, scene) -> dict:
    """Every light but the area lights as Mitsuba scene-dict entries (oclgi/study/mitsuba.py)."""
    sphere = bounding_sphere(scene)
    out, counts = {}, {}
    for light in all_lights(scene):
        i = counts[light.table] = counts.get(light.table, -1) + 1
        if power(light, sphere).max() > 0:
            entry = light.to_mitsuba(mi, sphere)
            if entry is not None:  # None: a kind Mitsuba lacks (it warned)
                out[f"{light.table}_{i}"] = entry
    return out
