"""What can change after loading, by name, and the update that recomputes
only what depends on it (in the spirit of Mitsuba 3's ``mi.traverse``).

    >>> import oclgi
    >>> engine = oclgi.Engine(oclgi.load_file(oclgi.scene_path("cornell_box.toml")))
    >>> params = engine.parameters()
    >>> params["material.CornellBox-Original.obj:leftWall.albedo"]
    (0.63, 0.065, 0.05)
    >>> params["material.CornellBox-Original.obj:leftWall.albedo"] = (0.1, 0.6, 0.1)
    >>> params.update().changed
    ['material.CornellBox-Original.obj:leftWall.albedo']

The names (``Parameters.keys()``; ``print(params)`` lists them with their
values):

================================  ===============================================
``material.NAME.FIELD``           a material's emission and the numbers its
                                  kind reads (oclgi/scene/materials.py
                                  PARAMETERS: albedo, specular, exponent, ior,
                                  roughness, transmission); its kind and
                                  texture are fixed
``light.NAME.FIELD``              a point, spot, sun or sky light's numbers:
                                  position, intensity, direction, cone angles,
                                  irradiance, radiance; NAME its ``name``, or
                                  ``#i`` (its index among the scene's lights)
``camera``                        an ``oclgi.Camera``
``photons``, ``seed``,            the run's parameters (an engine: its
``max_depth``, ``method``,        defaults, a session: its own)
``radius``, ``extension``,
``count_emitted``
================================  ===============================================

What an update recomputes (``Updated`` says it):

- a material or a light: every photon path (a session re-traces its store at
  its pose; the compiled scene's tables are rebuilt, its trees kept);
- ``seed``, ``max_depth``: every photon path;
- ``photons``: only the paths added (traced) or dropped (taken out of the
  sums);
- ``camera``: only the camera's points;
- ``method``, ``radius``, ``extension``, ``count_emitted``: nothing is
  traced; the stored paths are summed again.

A session after ``update()`` equals, bit for bit, a fresh session opened
with the new values at its pose; an engine's later runs equal those of an
engine loaded with them. Values are checked when set (type and shape) and
when applied (ranges, by the same readers as scene files); a refused update
changes nothing.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace

from .errors import OclgiError
from .scene.lights import all_lights as _lights  # point lights first, then the others

MATERIAL_FIELDS = ("albedo", "emission", "specular", "exponent", "ior", "roughness", "transmission")
RUN_FIELDS = ("photons", "seed", "max_depth", "method", "radius", "extension", "count_emitted")
TRACE_FIELDS = ("seed", "max_depth")  # every path depends on them
ESTIMATE_FIELDS = ("method", "radius", "extension", "count_emitted")  # the sums only


@dataclass
class Updated:
    """What an update changed and what it recomputed."""

    changed: list[str] = field(default_factory=list)  # the parameters that changed
    paths_traced: int = 0  # photon paths traced (all of them, the added ones, or none)
    paths_dropped: int = 0  # stored paths taken out of the sums
    points_traced: int = 0  # camera points traced
    resummed: bool = False  # the stored paths summed again
    tables: bool = False  # materials' and emitters' device tables rebuilt
    seconds: float = 0.0


def _light_key(light, i: int) -> str:
    return f"light.{light.name if getattr(light, 'name', None) else f'#{i}'}"


def light_name(scene, light) -> str:
    """The parameters' name of ``light``, one of ``scene``'s lights ("light.NAME" or "light.#i")."""
    i = next(k for k, other in enumerate(_lights(scene)) if other is light)
    return _light_key(light, i)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_vector(v) -> bool:
    return isinstance(v, tuple) and len(v) in (2, 3) and all(_is_number(c) for c in v)


def values(scene, run, camera) -> dict:
    """Every parameter's current value (``run``: the RunParams in force;
    ``camera``: the camera in use, None for none)."""
    out = {}
    from .scene.materials import PARAMETERS

    for m in scene.materials:  # the numbers its kind reads, and its emission
        for f in MATERIAL_FIELDS:
            if f == "emission" or f in PARAMETERS[m.kind]:
                out[f"material.{m.name}.{f}"] = getattr(m, f)
    for i, light in enumerate(_lights(scene)):
        for f in fields(light):
            v = getattr(light, f.name)
            if f.name != "name" and (_is_number(v) or _is_vector(v)):
                out[f"{_light_key(light, i)}.{f.name}"] = v
    if camera is not None:
        out["camera"] = camera
    for f in RUN_FIELDS:
        out[f] = getattr(run, f)
    return out


def coerce(key: str, value, current):
    """``value`` in the type and shape of ``current``, or one clear error."""
    from .scene.scene import Camera

    if isinstance(current, Camera):
        if not isinstance(value, Camera):
            raise OclgiError(f"{key} takes an oclgi.Camera, got {type(value).__name__}")
        return value
    if isinstance(current, tuple):
        try:
            v = tuple(float(c) for c in value)
        except (TypeError, ValueError):
            raise OclgiError(f"{key} takes {len(current)} numbers, got {value!r}") from None
        if len(v) != len(current) or not all(math.isfinite(c) for c in v):
            raise OclgiError(f"{key} takes {len(current)} finite numbers, got {value!r}")
        return v
    for kind, what in ((bool, "true or false"), (str, "a name")):
        if isinstance(current, kind):
            if not isinstance(value, kind):
                raise OclgiError(f"{key} takes {what}, got {value!r}")
            return value
    if isinstance(current, int) and key in RUN_FIELDS:
        return value  # the run's readers check it (oclgi/params.py)
    if not _is_number(value) or not math.isfinite(value):
        raise OclgiError(f"{key} takes a finite number, got {value!r}")
    return float(value)


def changed_scene(scene, changes: dict):
    """A copy of ``scene`` with the material, light and camera changes (each
    material and light checked as a scene file's), and the run changes as a
    dict."""
    new = copy.copy(scene)
    new.materials = list(scene.materials)
    new.point_lights = list(scene.point_lights)
    new.lights = list(scene.lights)
    run = {}
    by_name = {m.name: i for i, m in enumerate(scene.materials)}
    lights = _lights(scene)
    light_index = {_light_key(light, i): i for i, light in enumerate(lights)}
    for key, value in changes.items():
        if key == "camera":
            new.camera = value
        elif key in RUN_FIELDS:
            run[key] = value
        elif key.startswith("material."):
            name, f = key[len("material."):].rsplit(".", 1)
            i = by_name[name]
            new.materials[i] = replace(new.materials[i], **{f: value})
        else:
            prefix, f = key.rsplit(".", 1)
            i = light_index[prefix]
            n_point = len(scene.point_lights)
            target, j = (new.point_lights, i) if i < n_point else (new.lights, i - n_point)
            target[j] = replace(target[j], **{f: value})
    for m in new.materials:
        m.validate()
    for light in _lights(new):
        light.validate(new.name)
    if "camera" in changes:
        from .scene.description import validate_camera

        new.camera = validate_camera(new.camera)
    return new, run


def kinds(changes: dict) -> set:
    """Which parts of a run the changes reach: "tables", "trace", "photons", "camera", "estimate"."""
    out = set()
    for key in changes:
        if key.startswith(("material.", "light.")):
            out.add("tables")
        elif key in TRACE_FIELDS:
            out.add("trace")
        elif key in ESTIMATE_FIELDS:
            out.add("estimate")
        else:
            out.add(key)  # "photons", "camera"
    return out


class Parameters(Mapping):
    """The parameters of an engine or a session (module doc): read them as
    a mapping, set some, then ``update()``."""

    def __init__(self, target):
        self._target = target
        self._values = target._parameter_values()
        self._pending: dict = {}

    def __getitem__(self, key):
        return self._pending[key] if key in self._pending else self._values[key]

    def __iter__(self):
        return iter(self._values)

    def __len__(self):
        return len(self._values)

    def __setitem__(self, key, value):
        if key not in self._values:
            close = [k for k in self._values if k.split(".")[:2] == key.split(".")[:2]][:8]
            raise OclgiError(f"no parameter {key!r}" + (f"; near it: {', '.join(close)}" if close else
                                                         "; Parameters.keys() lists them"))
        self._pending[key] = coerce(key, value, self._values[key])

    def update(self) -> Updated:
        """Apply what was set since the last update; what was recomputed.
        A refused update (a value out of range) changes nothing and keeps
        nothing pending."""
        changes = {k: v for k, v in self._pending.items() if v != self._values[k]}
        self._pending = {}
        if not changes:
            return Updated()
        result = self._target._apply_parameters(changes)
        result.changed = sorted(changes)
        self._values = self._target._parameter_values()
        return result

    def __repr__(self) -> str:
        width = max(map(len, self._values), default=0)
        rows = [f"{k:<{width}}  {self[k]!r}" + ("  (pending)" if k in self._pending else "") for k in self._values]
        return "\n".join([f"Parameters of {type(self._target).__name__}:", *rows])
