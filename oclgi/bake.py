"""Light baked into a mesh: the solution at the vertices of a tessellated
copy of the scene, as vertex colours in a glTF 2.0 file (``oclgi bake``).

Density estimation is view-independent, so the irradiance at the vertices
of the scene cut to a fine edge (oclgi/scene/tessellate.py) is a lighting
solution any tool can draw: Blender, three.js, Godot and Unity read glTF
vertex colours. The file holds one mesh per scene object (static geometry,
then each movable object by its name, placed where the engine has it), and
per vertex:

- ``COLOR_0``: what a viewer shows, linear as glTF defines it (8 bits,
  normalised): ``exposure`` x E / pi for ``irradiance`` (the radiance of a
  white diffuse surface under that light), ``exposure`` x L for
  ``radiance`` (emission plus the material's diffuse albedo x E / pi; the
  albedo is the material's, untextured), clipped to 1;
- ``_COLOR_SRGB``: the same colour sRGB-encoded, 8 bits, for tools that
  take vertex colours as sRGB;
- ``_IRRADIANCE`` (or ``_RADIANCE``): the value itself, float32, W/m^2
  (W/m^2/sr): no tone mapping, no clipping.
"""

from __future__ import annotations

import warnings

import numpy as np

from .errors import OclgiError, OclgiWarning

QUANTITIES = ("irradiance", "radiance")


def _srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _bytes(x: np.ndarray) -> np.ndarray:
    """(n, 3) in [0, 1] as (n, 4) RGBA uint8, alpha 255."""
    out = np.full((len(x), 4), 255, np.uint8)
    out[:, :3] = np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)
    return out


def vertex_values(engine, tess, irradiance: np.ndarray, quantity: str) -> np.ndarray:
    """(V, 3) float32: the irradiance, or the radiance L = Le + albedo E / pi
    with each vertex's source-triangle material."""
    if quantity == "irradiance":
        return np.asarray(irradiance, np.float32)
    scene = engine.scene
    mats = scene.tri_material[tess.vertex_tri]
    albedo = np.array([m.diffuse_albedo for m in scene.materials], np.float64)[mats]
    emission = np.array([m.emission for m in scene.materials], np.float64)[mats]
    if any(m.texture is not None or m.vertex_colours for m in scene.materials):
        warnings.warn("textures and vertex colours are not baked: the radiance uses each material's albedo",
                      OclgiWarning, stacklevel=3)
    return (emission + albedo * np.asarray(irradiance, np.float64) / np.pi).astype(np.float32)


def bake(engine, edge: float | None = None, quantity: str = "irradiance", exposure: float = 1.0,
         **estimate) -> "trimesh.Scene":  # noqa: F821
    """The solution at the vertices of the scene cut to ``edge`` (default:
    the disc radius), as a trimesh Scene (module doc); ``estimate``: the
    arguments of ``Engine.irradiance`` (method, photons, radius, ...)."""
    from .incremental.attached_points import AttachedPoints
    from .scene.tessellate import tessellate

    if quantity not in QUANTITIES:
        raise OclgiError(f"quantity must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
    if not (isinstance(exposure, (int, float)) and np.isfinite(exposure) and exposure > 0):
        raise OclgiError(f"exposure must be a positive number, got {exposure!r}")
    tess = tessellate(engine.scene, edge)
    placed = AttachedPoints(engine, tess.points(), as_loaded=True)
    placed.update()  # the movable objects' vertices where the engine has them
    points = placed.points
    est = engine.irradiance(points, **estimate)
    values = vertex_values(engine, tess, est.irradiance, quantity)
    out = baked_scene(engine.scene, tess, points.positions[:, :3], points.normals[:, :3], values, quantity,
                      exposure)
    out.metadata["oclgi"] = {"quantity": quantity, "exposure": float(exposure), "edge": float(tess.edge),
                             "photons": int(est.stats.photons), "method": est.stats.method,
                             "radius": float(est.stats.radius)}
    out.metadata["stats"] = est.stats
    return out


def baked_scene(scene, tess, positions, normals, values, quantity: str, exposure: float) -> "trimesh.Scene":  # noqa: F821
    """The glTF's scene (module doc) of the tessellation ``tess`` with its
    vertices at ``positions`` (V, 3), ``normals`` and ``values`` (V, 3),
    the irradiance or radiance there (also ``oclgi view``'s bake of the
    current pose)."""
    import trimesh

    shown = exposure * (values / np.pi if quantity == "irradiance" else values)
    positions = np.asarray(positions, np.float64)
    normals = np.asarray(normals, np.float64)
    out = trimesh.Scene()
    for obj, (a, b) in enumerate(scene.object_ranges()):
        faces = tess.faces[(tess.face_source >= a) & (tess.face_source < b)]
        if not len(faces):
            continue
        used = np.unique(faces)
        local = np.searchsorted(used, faces)
        mesh = trimesh.Trimesh(positions[used], local, vertex_normals=normals[used], process=False)
        mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=_bytes(shown[used]))
        mesh.vertex_attributes[f"_{quantity.upper()}"] = values[used]
        mesh.vertex_attributes["_COLOR_SRGB"] = _bytes(_srgb(shown[used]))
        out.add_geometry(mesh, geom_name=scene.objects[obj].name, node_name=scene.objects[obj].name)
    return out


def glb_bytes(scene) -> bytes:
    """``scene`` as the bytes of one GLB file."""
    import trimesh

    return trimesh.exchange.gltf.export_glb(scene, include_normals=True)


def write_glb(scene, path) -> None:
    """``scene`` as one GLB file at ``path``, whole or not at all."""
    from .io import atomic_path, write_bytes

    data = glb_bytes(scene)
    with atomic_path(path) as tmp:
        write_bytes(tmp, data)
