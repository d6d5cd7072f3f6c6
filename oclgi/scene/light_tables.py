"""The scene file's light tables ([[point_light]], [[spot_light]], [[sun]],
[sky]) read into the kinds of oclgi/scene/lights.py, each error one line
naming its key.

It stands apart from the kinds because it is the file's side only: its
units (candela, lux, lumens), its files (IES profiles and environment maps,
relative to the scene file) and its orientations (an IES light's frame, a
light animation's keyframes). A light made in Python or read from a glTF
(oclgi/scene/gltf_lights.py) never passes here. oclgi/scene/lights.py's
docstring lists the tables' keys and defaults.
"""

from __future__ import annotations

import numpy as np

from ..errors import OclgiError
from ..params import MAX_LENGTH as MAX_COORDINATE  # as for vertices (oclgi/scene/scene.py)
from . import values
from .lights import (ENVMAP_MAX_TEXELS, SKY_UP, SPOT_CONE_ANGLE, SPOT_CONE_DELTA, TABLES, EnvMapLight, IesLight,
                     PointLight, SkyLight, SpotLight, SunLight, _unit)

# The keys each table takes; any other is an error, as everywhere in a scene file.
_KEYS = {
    "point_light": {"position", "intensity", "candela", "colour", "name", "ies", "lumens", "direction", "c0", "matrix",
                    "path"},
    "spot_light": {"position", "direction", "intensity", "candela", "colour", "cone_angle", "cone_delta", "name",
                   "ies", "lumens", "c0", "path"},
    "sun": {"direction", "irradiance", "lux", "colour"},
    "sky": {"radiance", "hemisphere", "up", "map", "scale"},
}
# Keys that only an IES light takes (its flux and its orientation about the nadir).
_IES_ONLY = ("lumens", "c0", "matrix")


def read(desc: dict, base_dir=None) -> tuple[list, list]:
    """(point lights, other lights) from a scene description's light tables
    (an environment map's file is relative to ``base_dir``)."""
    points, others = [], []
    for name, many in TABLES.items():
        if name not in desc:
            continue
        if many:
            tables = [(f"{name}[{i}]", t) for i, t in enumerate(values.table_list(desc[name], name))]
        else:
            if not isinstance(desc[name], dict):
                raise OclgiError(f"{name}: expected one [{name}] table, got {desc[name]!r}")
            tables = [(name, desc[name])]
        for where, t in tables:
            values.check_keys(t, _KEYS[name], where)
            if "ies" in t:
                others.append(_read_ies(t, where, base_dir, spot=name == "spot_light"))
                continue
            given = [k for k in _IES_ONLY if k in t] + (["direction"] if name == "point_light" and "direction" in t
                                                        else [])
            if given:
                raise OclgiError(f"{where}.{given[0]} goes with ies (an IES profile's flux and orientation)")
            light = _READERS[name](t, where) if name != "sky" else _read_sky(t, where, base_dir)
            if "path" in t:
                light.path = _path(t["path"], f"{where}.path", 6 if name == "spot_light" else 3)
            (points if name == "point_light" else others).append(light)
    return points, others


def _path(rows, where: str, widest: int) -> tuple:
    """A light animation's keyframes: at least one row of 3 numbers
    (position), or of 6 for a spot (position and axis), finite and within
    the scene's coordinates; the axes not zero."""
    if not isinstance(rows, list) or not rows or not all(isinstance(r, list) for r in rows):
        raise OclgiError(f"{where}: expected a list of rows [x, y, z]" + (" or [x, y, z, dx, dy, dz]"
                                                                           if widest == 6 else ""))
    width = len(rows[0])
    if width not in (3, widest) or any(len(r) != width for r in rows):
        raise OclgiError(f"{where}: every row must have 3" + (" or every row 6" if widest == 6 else "") +
                         f" numbers, got rows of {sorted({len(r) for r in rows})}")
    out = []
    for i, r in enumerate(rows):
        row = values.vec3(r[:3], f"{where}[{i}]", MAX_COORDINATE)
        if width == 6:
            row += tuple(_unit(values.vec3(r[3:], f"{where}[{i}] axis"), f"{where}[{i}] axis"))
        out.append(tuple(float(c) for c in row))
    return tuple(out)


def _required(t: dict, key: str, where: str):
    if key not in t:
        raise OclgiError(f"{where}.{key}: required")
    return t[key]


_UNITS = {"intensity": "W/sr", "irradiance": "W/m^2"}


def _photometric(t: dict, where: str, radiometric: str, photometric: str, convert, unit: str):
    """``radiometric`` (3 numbers), or ``photometric`` with an optional ``colour``."""
    if photometric in t:
        if radiometric in t:
            raise OclgiError(f"{where}: give {radiometric} ({_UNITS[radiometric]}) or {photometric}, not both")
        value = values.number(t[photometric], f"{where}.{photometric}")
        if not value > 0:
            raise OclgiError(f"{where}.{photometric}: expected {unit} > 0, got {t[photometric]!r}")
        colour = values.vec3(t.get("colour", (1.0, 1.0, 1.0)), where + ".colour")
        return values.radiant(convert(value, colour), f"{where}.{photometric}")
    if "colour" in t:
        raise OclgiError(f"{where}.colour goes with {photometric}; an {radiometric} has its own colour")
    return values.radiant(_required(t, radiometric, where), f"{where}.{radiometric}")


def _direction(t: dict, key: str, where: str):
    v = values.vec3(_required(t, key, where), f"{where}.{key}")
    return tuple(float(x) for x in _unit(v, f"{where}.{key}"))


def _name(t: dict, where: str) -> str | None:
    """A light's optional name (light animations move a light by it)."""
    name = t.get("name")
    if name is not None and (not isinstance(name, str) or not name.strip()):
        raise OclgiError(f"{where}.name: expected a non-empty string, got {name!r}")
    return name


def _read_point(t: dict, where: str) -> PointLight:
    from ..photometry import intensity_from_candela

    return PointLight(values.vec3(t.get("position"), where + ".position", MAX_COORDINATE),
                      _photometric(t, where, "intensity", "candela", intensity_from_candela, "a luminous intensity"),
                      name=_name(t, where))


def _read_spot(t: dict, where: str) -> SpotLight:
    from ..photometry import intensity_from_candela

    light = SpotLight(
        position=values.vec3(_required(t, "position", where), where + ".position", MAX_COORDINATE),
        direction=_direction(t, "direction", where),
        intensity=_photometric(t, where, "intensity", "candela", intensity_from_candela, "a luminous intensity"),
        cone_angle=values.number(t.get("cone_angle", SPOT_CONE_ANGLE), where + ".cone_angle"),
        cone_delta=values.number(t.get("cone_delta", SPOT_CONE_DELTA), where + ".cone_delta"), name=_name(t, where))
    if "cone_delta" not in t:  # the default band, within a narrow cone
        light.cone_delta = min(light.cone_delta, light.cone_angle)
    light.validate(where)
    return light


def _read_ies(t: dict, where: str, base_dir, spot: bool) -> IesLight:
    """A point or spot light with ``ies = FILE``: the profile, its scaling
    (``candela``: the peak; ``lumens``: the flux), ``colour`` and orientation."""
    from . import ies

    if "intensity" in t:
        raise OclgiError(f"{where}.intensity: an IES light's intensity is its file's candela (rescale it with "
                         "candela = the peak, or lumens = the flux)")
    if "candela" in t and "lumens" in t:
        raise OclgiError(f"{where}: give candela (the peak) or lumens (the flux), not both")
    profile = ies.read(values.file_path(t["ies"], where + ".ies", "an IES file name", base_dir), where + ".ies")
    direction, c0 = _ies_frame(t, where, spot)
    light = IesLight(position=values.vec3(_required(t, "position", where), where + ".position", MAX_COORDINATE),
                     profile=profile, direction=direction, c0=c0,
                     colour=values.vec3(t.get("colour", (1.0, 1.0, 1.0)), where + ".colour"), name=_name(t, where),
                     where=where)
    if spot:
        light.cone_angle = values.number(t.get("cone_angle", SPOT_CONE_ANGLE), where + ".cone_angle")
        light.cone_delta = values.number(t.get("cone_delta", min(SPOT_CONE_DELTA, light.cone_angle)),
                                         where + ".cone_delta")
    for key, unit, current in (("candela", "a luminous intensity (cd)", lambda: profile.peak),
                               ("lumens", "a luminous flux (lm)", lambda: light.flux)):
        if key in t:
            value = values.number(t[key], f"{where}.{key}")
            if not value > 0:
                raise OclgiError(f"{where}.{key}: expected {unit} > 0, got {t[key]!r}")
            light.scale = value / current()
    light.validate(where)
    return light


def _ies_frame(t: dict, where: str, spot: bool):
    """(nadir, c0) of an IES light: ``matrix`` (a rotation: the luminaire's x
    = C 0, y = C 90, z = zenith as its columns), or ``direction`` and ``c0``."""
    if "matrix" in t:
        other = [k for k in ("direction", "c0") if k in t]
        if other:
            raise OclgiError(f"{where}: give matrix or {' and '.join(other)}, not both")
        rows = t["matrix"]
        if not isinstance(rows, (list, tuple)) or len(rows) != 3:
            raise OclgiError(f"{where}.matrix: expected 3 rows of 3 numbers, got {rows!r}")
        m = np.array([values.vec3(r, f"{where}.matrix[{k}]") for k, r in enumerate(rows)])
        if np.abs(m.T @ m - np.eye(3)).max() > 1e-6 or np.linalg.det(m) < 0:
            raise OclgiError(f"{where}.matrix: expected a rotation (orthonormal columns, determinant +1), got "
                             f"{rows!r}")
        return tuple(float(x) for x in -m[:, 2]), tuple(float(x) for x in m[:, 0])
    raw = _required(t, "direction", where) if spot else t.get("direction", (0.0, -1.0, 0.0))
    nadir = _unit(values.vec3(raw, where + ".direction"), where + ".direction")
    if "c0" in t:
        c = _unit(values.vec3(t["c0"], where + ".c0"), where + ".c0")
    else:
        c = np.array([1.0, 0.0, 0.0]) if abs(nadir[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    c = c - (c @ nadir) * nadir
    if not np.linalg.norm(c) > 1e-6:
        raise OclgiError(f"{where}.c0: must not be parallel to the direction (the nadir), got {t.get('c0')!r}")
    c /= np.linalg.norm(c)
    return tuple(float(x) for x in nadir), tuple(float(x) for x in c)


def _read_sun(t: dict, where: str) -> SunLight:
    from ..photometry import irradiance_from_lux

    return SunLight(direction=_direction(t, "direction", where),
                    irradiance=_photometric(t, where, "irradiance", "lux", irradiance_from_lux, "an illuminance"))


def _read_sky(t: dict, where: str, base_dir=None):
    if "map" in t:
        return _read_envmap(t, where, base_dir)
    if "scale" in t:
        raise OclgiError(f"{where}.scale goes with map; a radiance has its own size")
    hemisphere = t.get("hemisphere", True)
    if not isinstance(hemisphere, bool):
        raise OclgiError(f"{where}.hemisphere: expected true or false, got {hemisphere!r}")
    up = tuple(float(x) for x in _unit(values.vec3(t.get("up", SKY_UP), where + ".up"), where + ".up"))
    return SkyLight(radiance=values.radiant(_required(t, "radiance", where), where + ".radiance"),
                    hemisphere=hemisphere, up=up)


def _read_envmap(t: dict, where: str, base_dir) -> EnvMapLight:
    """``map`` (an image file, through OpenImageIO) times ``scale``."""
    other = sorted({"radiance", "hemisphere", "up"} & set(t))
    if other:
        raise OclgiError(f"{where}: map takes no {', '.join(other)} (the image is the radiance, +y its zenith)")
    path = values.file_path(t["map"], where + ".map", "an image file name", base_dir)
    scale = values.number(t.get("scale", 1.0), where + ".scale")
    if not scale > 0:
        raise OclgiError(f"{where}.scale: expected a number > 0, got {t['scale']!r}")
    light = EnvMapLight(read_image(path, where + ".map") * scale, name=path.name)
    light.validate(where)
    return light


def read_image(path, where: str) -> np.ndarray:
    """An image file as (H, W, 3) float64 (a grey one repeated to RGB; alpha dropped)."""
    from pathlib import Path

    import OpenImageIO as oiio

    try:
        found = Path(path).is_file()
    except OSError as exc:  # a name too long for the file system, a permission
        raise OclgiError(f"{where}: cannot read {path}: {exc.strerror or exc}") from None
    if not found:
        raise OclgiError(f"{where}: image file not found: {path}")
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OclgiError(f"{where}: cannot read {path}: {oiio.geterror().strip() or 'not an image'}")
    try:
        spec = inp.spec()
        if spec.width * spec.height > ENVMAP_MAX_TEXELS:
            raise OclgiError(f"{where}: {path.name} has {spec.width} x {spec.height} texels; at most "
                             f"{ENVMAP_MAX_TEXELS:,}")
        pixels = inp.read_image(format="float")
    finally:
        inp.close()
    if pixels is None:
        raise OclgiError(f"{where}: cannot read {path}: {oiio.geterror().strip()}")
    a = np.asarray(pixels, np.float64).reshape(spec.height, spec.width, spec.nchannels)
    a = np.repeat(a[..., :1], 3, axis=2) if spec.nchannels < 3 else a[..., :3]
    return a


_READERS = {"point_light": _read_point, "spot_light": _read_spot, "sun": _read_sun}
