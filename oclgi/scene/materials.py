"""Materials: every kind of surface oclgi scatters light from, in one place.

A material's kind decides how it scatters (``kernels/bsdf.h`` is the only
device code that says so); this module owns, per kind, its parameters and
their defaults, reading them from a scene file's table, an MTL block or a
glTF PBR material, their validation, the device record
(``oclgi.cl.layout.Material``), the largest reflectance (``r_max``, for the
study's bounds) and the conversion to Mitsuba 3 (``to_mitsuba``).

==================  ==========================================================
kind                parameters (defaults)
==================  ==========================================================
``diffuse``         ``albedo`` (0.5): Lambertian reflectance, times
                    ``texture`` (an image file, oclgi/scene/textures.py)
``phong``           ``albedo`` (Kd), ``specular`` (Ks), ``exponent`` (Ns, 10):
                    the energy-conserving modified Phong of Lafortune and
                    Willems, ``Kd / pi + Ks (n + 2) / (2 pi) cos^n alpha``
``mirror``          ``specular`` (1): a perfect mirror's reflectance
``dielectric``      ``ior`` (1.5), ``specular`` (1, tint of the reflection),
                    ``transmission`` (1, tint of the refraction): smooth
                    glass or water, Fresnel reflection and refraction, total
                    internal reflection; the normal points outside. MTL
                    glass (illum 4, 6, 7, 9) is clear at its ``Ni``: its
                    ``Ks`` and ``Tf`` are not tints, as Blender's and
                    three.js's OBJ importers read them
``conductor``       ``specular`` (1, the reflectance F at every angle, as
                    Mitsuba's ``roughconductor`` with ``material = "none"``),
                    ``roughness`` (0.1, GGX alpha): a rough metal
``rough_dielectric``  ``ior``, ``roughness``, ``specular``, ``transmission``:
                    rough glass (GGX, Walter et al. 2007)
==================  ==========================================================

Every kind takes ``emission`` (radiance, W/m^2/sr, on the normal's side;
diffuse and Phong surfaces only) and ``twosided`` (true: both sides scatter
alike; false: the back of the surface is black; dielectrics always have two
sides, inside and outside).

Why the modified Phong has a stricter bound than ``Kd + Ks <= 1``: a photon
never gains power at a bounce (so no stored segment exceeds the fixed-point
bound of ``kernels/oclgi_types.h``) when every sample's weight f cos / pdf
is at most 1; the specular lobe, sampled by cos^n alpha, weighs up to
``Ks (n + 2) / (n + 1)``, so ``max(Kd) + max(Ks) (n + 2) / (n + 1) <= 1``
is required. A scene file's table that breaks it is an error; an MTL
material is scaled down to it with a warning.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from ..cl import constants
from ..cl.layout import Material as MaterialRecord
from ..errors import OclgiError, OclgiWarning

KINDS = {
    "diffuse": constants.BSDF_DIFFUSE,
    "phong": constants.BSDF_PHONG,
    "mirror": constants.BSDF_MIRROR,
    "dielectric": constants.BSDF_DIELECTRIC,
    "conductor": constants.BSDF_CONDUCTOR,
    "rough_dielectric": constants.BSDF_ROUGH_DIELECTRIC,
}
# Kinds that scatter into single directions: no density estimation on them
# (they store no impacts, camera rays pass on to the next surface).
DELTA = {"mirror", "dielectric"}
# Kinds whose surfaces reflect a diffuse part, estimated at the point.
DIFFUSE_PART = {"diffuse", "phong"}
# The parameters each kind reads (besides emission and twosided).
PARAMETERS = {
    "diffuse": ("albedo", "texture"),
    "phong": ("albedo", "specular", "exponent"),
    "mirror": ("specular",),
    "dielectric": ("ior", "specular", "transmission"),
    "conductor": ("specular", "roughness"),
    "rough_dielectric": ("ior", "roughness", "specular", "transmission"),
}
TABLE_KEYS = {"kind", "albedo", "emission", "specular", "exponent", "ior", "roughness", "transmission",
              "twosided", "texture"}
MAX_EXPONENT = 1e6  # a Phong lobe narrower than float32's cos^n can resolve is a mirror
MIN_ROUGHNESS = 1e-3  # GGX alpha below this is numerically a mirror: say mirror
MAX_IOR = 10.0
DARK_GLASS = 0.1  # glass transmitting less than this looks black: said when a scene is made


@dataclass
class Material:
    """A surface's material (see the module's table for what each kind reads)."""

    name: str
    albedo: tuple[float, float, float] = (0.5, 0.5, 0.5)
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kind: str = "diffuse"
    specular: tuple[float, float, float] = (1.0, 1.0, 1.0)
    exponent: float = 10.0
    ior: float = 1.5
    roughness: float = 0.1
    transmission: tuple[float, float, float] = (1.0, 1.0, 1.0)
    twosided: bool = True
    # (H, W, 3) float32 linear reflectance multiplying the albedo
    # (oclgi/scene/textures.py); diffuse surfaces only
    texture: np.ndarray | None = field(default=None, repr=False, compare=False)
    # the albedo times the mesh's vertex colours (glTF COLOR_0, PLY colours); diffuse surfaces only
    vertex_colours: bool = False

    @property
    def delta(self) -> bool:
        return self.kind in DELTA

    @property
    def diffuse_albedo(self) -> tuple[float, float, float]:
        """The reflectance of the part estimated at the point (albedo / pi
        times the irradiance): the albedo of diffuse and Phong surfaces, 0
        for the others (their light is reached by tracing on)."""
        return tuple(self.albedo) if self.kind in DIFFUSE_PART else (0.0, 0.0, 0.0)

    def r_max(self) -> np.ndarray:
        """The largest fraction of the light arriving that the surface sends
        on, per channel (the study's bounds, oclgi/study/bound_inputs.py)."""
        a = np.asarray(self.albedo, np.float64)
        s = np.asarray(self.specular, np.float64)
        t = np.asarray(self.transmission, np.float64)
        if self.kind == "diffuse":
            return a
        if self.kind == "phong":
            return a + s
        if self.kind in ("mirror", "conductor"):
            return s
        return np.maximum(s, t)

    def validate(self) -> None:
        where = f"material {self.name!r}"
        if self.kind not in KINDS:
            raise OclgiError(f"{where}: unknown kind {self.kind!r} (kinds: {', '.join(KINDS)})")
        for key in ("albedo", "specular", "transmission"):
            v = np.asarray(getattr(self, key), float)
            if v.shape != (3,) or not np.isfinite(v).all() or (v < 0).any() or (v > 1).any():
                raise OclgiError(f"{where}: {key} must be 3 numbers in [0, 1], got {getattr(self, key)}")
        e = np.asarray(self.emission, float)
        if e.shape != (3,) or not np.isfinite(e).all() or (e < 0).any():
            raise OclgiError(f"{where}: emission must be 3 numbers >= 0, got {self.emission}")
        if e.max() > 0 and self.kind not in DIFFUSE_PART:
            raise OclgiError(f"{where}: a {self.kind} surface cannot emit (emission goes with diffuse or "
                             "phong materials)")
        if self.texture is not None:
            if self.kind != "diffuse":
                raise OclgiError(f"{where}: a texture goes with a diffuse material, not {self.kind}")
            t = self.texture
            if not (isinstance(t, np.ndarray) and t.dtype == np.float32 and t.ndim == 3 and t.shape[2] == 3):
                raise OclgiError(f"{where}: texture must be an (H, W, 3) float32 array (oclgi.scene.textures)")
        if self.vertex_colours and self.kind != "diffuse":
            raise OclgiError(f"{where}: vertex colours go with a diffuse material, not {self.kind}")
        if not isinstance(self.twosided, (bool, np.bool_)):
            raise OclgiError(f"{where}: twosided must be true or false, got {self.twosided!r}")
        if not (isinstance(self.exponent, (int, float)) and 0 <= self.exponent <= MAX_EXPONENT):
            raise OclgiError(f"{where}: exponent must be a number from 0 to {MAX_EXPONENT:g}, got {self.exponent!r}")
        if not (isinstance(self.ior, (int, float)) and 1.0 <= self.ior <= MAX_IOR) or self.ior == 1.0 and \
                self.kind in ("dielectric", "rough_dielectric"):
            raise OclgiError(f"{where}: ior must be a number above 1 and at most {MAX_IOR:g}, got {self.ior!r}")
        if not (isinstance(self.roughness, (int, float)) and MIN_ROUGHNESS <= self.roughness <= 1.0):
            raise OclgiError(f"{where}: roughness (GGX alpha) must be a number from {MIN_ROUGHNESS:g} to 1, "
                             f"got {self.roughness!r} (a smooth surface is kind 'mirror' or 'dielectric')")
        if self.kind == "phong":
            bound = phong_weight_bound(self.albedo, self.specular, self.exponent)
            if bound > 1.0 + 1e-9:
                raise OclgiError(f"{where}: max(albedo) + max(specular) (n + 2) / (n + 1) is {bound:.4g}; it must be "
                                 "at most 1 (so no photon gains power at a bounce: oclgi/scene/materials.py)")


def phong_weight_bound(albedo, specular, exponent) -> float:
    """The largest weight a modified Phong sample can have (module doc)."""
    return float(max(albedo)) + float(max(specular)) * (exponent + 2.0) / (exponent + 1.0)


def fit_phong(albedo, specular, exponent):
    """(albedo, specular) scaled down together so that the Phong weight
    bound holds (an MTL file's Kd + Ks often exceed it), and the factor."""
    bound = phong_weight_bound(albedo, specular, exponent)
    if bound <= 1.0:
        return tuple(albedo), tuple(specular), 1.0
    k = 1.0 / bound
    # float32 on the device: round down so the device's sum stays <= 1
    k = float(np.nextafter(np.float32(k), np.float32(0)))
    return tuple(k * c for c in albedo), tuple(k * c for c in specular), k


def from_table(name: str, table: dict, base: Material, read) -> Material:
    """``base`` with a scene file's material table applied (``[mesh.materials.NAME]``).

    ``read`` is description.py's reader set (vec3, radiant, number), so the
    values are checked exactly as every other number of a scene file."""
    kind = table.get("kind", base.kind)
    if not isinstance(kind, str) or kind not in KINDS:
        raise OclgiError(f"{name}.kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    m = replace(base, kind=kind)
    if kind != "diffuse":
        m.texture = None  # a file's texture and colours went with the diffuse surface this table replaces
        m.vertex_colours = False
    for key in ("albedo", "specular", "transmission"):
        if key in table:
            setattr(m, key, read.vec3(table[key], f"{name}.{key}"))
    if "emission" in table:
        m.emission = read.radiant(table["emission"], f"{name}.emission")
    for key in ("exponent", "ior", "roughness"):
        if key in table:
            setattr(m, key, read.number(table[key], f"{name}.{key}"))
    if "texture" in table:
        m.texture = read.texture(table["texture"], f"{name}.texture")
    if "twosided" in table:
        if not isinstance(table["twosided"], bool):
            raise OclgiError(f"{name}.twosided: expected true or false, got {table['twosided']!r}")
        m.twosided = table["twosided"]
    unused = sorted(k for k in table if k in TABLE_KEYS and k not in PARAMETERS[kind]
                    and k not in ("kind", "emission", "twosided"))
    if unused:
        raise OclgiError(f"{name}: a {kind} material takes no {', '.join(unused)} "
                         f"(it reads {', '.join(PARAMETERS[kind])})")
    return m


@dataclass
class FileMaterial:
    """What a mesh file says about a material, before oclgi decides its kind
    (``from_file``): MTL keys by name, glTF's PBR factors."""

    albedo: tuple | None = None  # Kd / baseColorFactor
    emission: tuple | None = None  # Ke / emissiveFactor (x strength)
    specular: tuple | None = None  # Ks
    exponent: float | None = None  # Ns
    ior: float | None = None  # Ni / KHR_materials_ior
    transmission: tuple | None = None  # Tf
    dissolve: float | None = None  # d (1 - Tr)
    illum: int | None = None
    metallic: float | None = None  # glTF metallicFactor
    roughness: float | None = None  # glTF roughnessFactor (perceptual)
    transmission_factor: float | None = None  # KHR_materials_transmission
    textures: dict = field(default_factory=dict)  # map_Kd, baseColorTexture, ... -> file name
    source: str = "mtl"


# MTL illumination models: 0-2 diffuse (Phong where Ks > 0), 3 and 5
# mirror, 4, 6, 7 glass (MTL's ray-traced, Fresnel and refraction models);
# 8 and 9 (their non-ray-traced twins) the same.
_ILLUM = {0: "diffuse", 1: "diffuse", 2: "phong", 3: "mirror", 4: "dielectric", 5: "mirror",
          6: "dielectric", 7: "dielectric", 8: "mirror", 9: "dielectric"}


ALBEDO_TEXTURES = ("map_Kd", "baseColorTexture")


def from_file(label: str, fm: FileMaterial | None, default: Material, quiet: bool = False,
              read_texture=None) -> Material:
    """The scene material for a mesh file's material ``label``; a property
    oclgi cannot honour is one warning naming it and the material (none
    when ``quiet``: the scene file replaces the material). ``read_texture(
    value)``: the albedo texture a file names (``map_Kd``) or holds (glTF),
    as oclgi/scene/textures.py returns it, or None when it is missing."""
    m = replace(default, name=label)
    if fm is None:
        return m
    ignored = []
    if fm.source == "gltf":
        _from_gltf(m, fm, ignored)
    else:
        _from_mtl(m, fm, ignored)
    if fm.emission is not None:
        m.emission = tuple(fm.emission)
        if max(m.emission) > 0 and m.kind not in DIFFUSE_PART:
            ignored.append("emission (a " + m.kind + " surface does not emit)")
            m.emission = (0.0, 0.0, 0.0)
    for key, value in sorted(fm.textures.items(), key=lambda kv: kv[0]):
        shown = repr(value) if isinstance(value, str) else "(embedded image)"
        if key in ALBEDO_TEXTURES and m.kind == "diffuse" and read_texture is not None:
            m.texture = read_texture(value)
            if m.texture is None:
                ignored.append(f"{key} {shown} (not found: the factor is used)")
        elif key in ALBEDO_TEXTURES:
            ignored.append(f"{key} {shown} (textures go with diffuse surfaces: the factor is used)")
        else:
            ignored.append(f"{key} {shown} (not supported: the factor is used)")
    if ignored and not quiet:
        warnings.warn(f"material {label!r}: ignored " + "; ".join(ignored), OclgiWarning, stacklevel=4)
    return m


def _from_mtl(m: Material, fm: FileMaterial, ignored: list) -> None:
    illum = fm.illum if fm.illum is not None else 2
    kind = _ILLUM.get(illum)
    if kind is None:
        ignored.append(f"illum {illum} (unknown model: read as 2)")
        kind = "phong"
    if fm.albedo is not None:
        m.albedo = tuple(fm.albedo)
    ks = fm.specular
    if kind == "phong" and not (ks is not None and max(ks) > 0):
        kind = "diffuse"
    m.kind = kind
    if kind == "phong":
        m.exponent = float(min(max(fm.exponent if fm.exponent is not None else 10.0, 0.0), MAX_EXPONENT))
        albedo, spec, k = fit_phong(m.albedo, ks, m.exponent)
        if k < 1.0:
            ignored.append(f"part of Kd + Ks (scaled by {k:.3g} to conserve energy)")
        m.albedo, m.specular = albedo, spec
    elif kind == "mirror":
        m.specular = tuple(ks) if ks is not None else (1.0, 1.0, 1.0)
        _unused_albedo(fm, "Kd", ignored)
    elif kind == "dielectric":
        m.ior = float(fm.ior) if fm.ior is not None and fm.ior > 1.0 else 1.5
        if fm.ior is not None and not fm.ior > 1.0:
            ignored.append(f"Ni {fm.ior:g} (glass needs an index above 1: 1.5 used)")
        # The common reading of MTL glass (Blender's and three.js's OBJ importers): clear glass
        # whose reflection and refraction are Fresnel's at Ni. Neither importer tints by Tf, and
        # Blender takes Ks as the specular level, not a tint; a scene file's table tints it.
        m.specular, m.transmission = (1.0, 1.0, 1.0), (1.0, 1.0, 1.0)
        for key, value in (("Ks", ks), ("Tf", fm.transmission)):
            if value is not None and tuple(value) != (1.0, 1.0, 1.0):
                ignored.append(f"{key} {' '.join(f'{c:g}' for c in value)} (MTL glass is read as clear, as "
                               "Blender's and three.js's importers read it; tint it with specular or "
                               "transmission in a [mesh.materials] table)")
        _unused_albedo(fm, "Kd", ignored)
    if fm.dissolve is not None and fm.dissolve < 1.0:
        ignored.append(f"d {fm.dissolve:g} (partial transparency)")
    if kind in ("diffuse",) and ks is not None and max(ks) > 0:
        ignored.append(f"Ks (illum {illum} has no highlight)")


def _unused_albedo(fm: FileMaterial, key: str, ignored: list) -> None:
    if fm.albedo is not None and max(fm.albedo) > 0:
        ignored.append(f"{key} (a {'mirror' if fm.illum in (3, 5, 8) else 'glass'} surface has no diffuse part)")


def _from_gltf(m: Material, fm: FileMaterial, ignored: list) -> None:
    """glTF 2.0 metallic-roughness: metallic 1 is a GGX conductor of
    F = baseColor and alpha = roughness^2 (glTF's perceptual roughness),
    metallic 0 a diffuse surface of the base colour (its dielectric
    highlight is dropped: said), KHR_materials_transmission 1 rough glass."""
    base = tuple(fm.albedo) if fm.albedo is not None else (1.0, 1.0, 1.0)
    metallic = 1.0 if fm.metallic is None else float(fm.metallic)
    rough = 1.0 if fm.roughness is None else float(fm.roughness)
    alpha = min(max(rough * rough, MIN_ROUGHNESS), 1.0)
    if fm.transmission_factor is not None and fm.transmission_factor > 0.5:
        m.kind = "dielectric" if alpha <= MIN_ROUGHNESS else "rough_dielectric"
        m.ior = float(fm.ior) if fm.ior is not None and fm.ior > 1.0 else 1.5
        m.roughness, m.transmission, m.specular = alpha, base, (1.0, 1.0, 1.0)
        if fm.transmission_factor < 1.0:
            ignored.append(f"transmission {fm.transmission_factor:g} (read as 1)")
        return
    if metallic >= 0.5:
        m.kind = "mirror" if alpha <= MIN_ROUGHNESS else "conductor"
        m.specular, m.roughness = base, alpha
        if metallic < 1.0:
            ignored.append(f"metallic {metallic:g} (read as 1)")
        return
    m.kind, m.albedo = "diffuse", base
    if metallic > 0.0:
        ignored.append(f"metallic {metallic:g} (read as 0)")
    if fm.roughness is not None and rough < 0.5:
        ignored.append("the dielectric highlight of metallic-roughness (a diffuse surface is used)")


def record(materials: list[Material], texture_index: list[int] | None = None) -> np.ndarray:
    """The device's ``Material`` records (oclgi/cl/layout.py, kernels/bsdf.h);
    ``texture_index``: each material's texture in the scene's packed
    textures (oclgi/scene/textures.py), -1 for none."""
    rec = np.zeros(len(materials), MaterialRecord)
    for i, m in enumerate(materials):
        r = rec[i]
        r["kind"] = KINDS[m.kind]
        r["flags"] = ((constants.MATERIAL_TWOSIDED if m.twosided else 0) | (constants.MATERIAL_DELTA if m.delta else 0)
                      | (constants.MATERIAL_VERTEX_COLOUR if m.vertex_colours else 0))
        # dielectrics read their transmission tint from the albedo slot
        r["albedo"] = m.transmission if m.kind in ("dielectric", "rough_dielectric") else m.diffuse_albedo
        r["emission"] = m.emission
        r["specular"] = m.specular if m.kind != "diffuse" else (0.0, 0.0, 0.0)
        r["exponent"], r["ior"], r["roughness"] = m.exponent, m.ior, m.roughness
        r["texture"] = texture_index[i] if texture_index is not None else -1
        if m.kind == "phong" and phong_weight_bound(r["albedo"], r["specular"], float(r["exponent"])) > 1.0 + 1e-6:
            raise OclgiError(f"material {m.name!r}: the Phong weight bound fails in float32")
    return rec


def to_mitsuba(m: Material) -> dict:
    """The Mitsuba 3 BSDF dict of a material (the study's references).

    Modified Phong has no Mitsuba 3 plugin: it becomes a blend of a diffuse
    lobe and a GGX lobe of about its width (alpha = sqrt(2 / (n + 2)), the
    usual Phong-to-microfacet match), an approximation: a comparison of a
    Phong scene with Mitsuba says so."""
    rgb = lambda v: {"type": "rgb", "value": [float(c) for c in v]}  # noqa: E731
    if m.kind == "diffuse":
        bsdf = {"type": "diffuse", "reflectance": rgb(m.albedo)}
    elif m.kind == "phong":
        alpha = math.sqrt(2.0 / (m.exponent + 2.0))
        w = max(m.specular) / max(max(m.specular) + max(m.albedo), 1e-12)
        spec = [c / w if w > 0 else 0.0 for c in m.specular]
        diff = [c / (1 - w) if w < 1 else 0.0 for c in m.albedo]
        bsdf = {"type": "blendbsdf", "weight": float(w),
                "bsdf_0": {"type": "diffuse", "reflectance": rgb(diff)},
                "bsdf_1": {"type": "roughconductor", "material": "none", "distribution": "ggx",
                           "alpha": float(alpha), "specular_reflectance": rgb([min(c, 1.0) for c in spec])}}
    elif m.kind == "mirror":
        bsdf = {"type": "conductor", "material": "none", "specular_reflectance": rgb(m.specular)}
    elif m.kind == "conductor":
        bsdf = {"type": "roughconductor", "material": "none", "distribution": "ggx", "alpha": float(m.roughness),
                "specular_reflectance": rgb(m.specular)}
    elif m.kind == "dielectric":
        bsdf = {"type": "dielectric", "int_ior": float(m.ior), "ext_ior": 1.0,
                "specular_reflectance": rgb(m.specular), "specular_transmittance": rgb(m.transmission)}
    else:
        bsdf = {"type": "roughdielectric", "distribution": "ggx", "alpha": float(m.roughness),
                "int_ior": float(m.ior), "ext_ior": 1.0,
                "specular_reflectance": rgb(m.specular), "specular_transmittance": rgb(m.transmission)}
    if m.twosided and m.kind not in ("dielectric", "rough_dielectric"):
        bsdf = {"type": "twosided", "bsdf": bsdf}
    return bsdf
