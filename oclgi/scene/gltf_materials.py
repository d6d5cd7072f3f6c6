"""What a glTF material says beyond trimesh's reading: the extensions
``KHR_materials_emissive_strength`` (a factor on the emission),
``KHR_materials_transmission`` (the fraction of light transmitted: glass)
and ``KHR_materials_ior`` (its index of refraction), read from the file's
JSON by material name (oclgi/scene/materials.py turns them into a kind)."""

from __future__ import annotations

import math

from .gltf_lights import document

EMISSIVE_STRENGTH = "KHR_materials_emissive_strength"
TRANSMISSION = "KHR_materials_transmission"
IOR = "KHR_materials_ior"
# (what extensions() calls it, the extension, its field, the field's default)
_READ = (("emissive_strength", EMISSIVE_STRENGTH, "emissiveStrength", 1.0),
         ("transmission", TRANSMISSION, "transmissionFactor", 0.0), ("ior", IOR, "ior", 1.5))


def _number(table, key, default):
    value = table.get(key, default) if isinstance(table, dict) else default
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value) else default


def extensions(data: bytes, suffix: str) -> dict:
    """{material name: {"emissive_strength", "transmission", "ior"}} of the
    materials that have any of the three extensions."""
    doc = document(data, suffix)
    mats = doc.get("materials") if doc is not None else None
    out = {}
    for m in mats if isinstance(mats, list) else []:
        ext = m.get("extensions") if isinstance(m, dict) else None
        if not isinstance(ext, dict) or not isinstance(m.get("name"), str):
            continue
        found = {key: _number(ext[name], field, default) for key, name, field, default in _READ if name in ext}
        if found:
            out[m["name"].strip()] = found
    return out


def apply(materials: dict, found: dict) -> None:
    """The extensions' values into the mesh's FileMaterials (keyed by name)."""
    for name, values in found.items():
        fm = materials.get(name)
        if fm is None:
            continue
        if "emissive_strength" in values and fm.emission is not None:
            fm.emission = tuple(c * values["emissive_strength"] for c in fm.emission)
        if "transmission" in values:
            fm.transmission_factor = values["transmission"]
        if "ior" in values:
            fm.ior = values["ior"]
