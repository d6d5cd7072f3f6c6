"""Loading triangle meshes from files.

OBJ goes through oclgi's own reader (:mod:`oclgi.scene.obj`); PLY, glTF/GLB,
STL and OFF through trimesh. A ``.zip`` holding one mesh file is read in
memory (Sponza ships that way). Every mesh comes back as float64 vertices,
int64 faces and one material name per face ('' when the file names none),
plus the materials the file itself defines.
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import OclgiError
from .obj import MtlMaterial, read_obj

TRIMESH_TYPES = {".ply", ".glb", ".gltf", ".stl", ".off"}
MESH_TYPES = {".obj"} | TRIMESH_TYPES


@dataclass
class LoadedMesh:
    vertices: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray  # (F,) index into names
    names: list[str]
    materials: dict[str, MtlMaterial]


def load_mesh(path: Path) -> LoadedMesh:
    path = Path(path)
    if not path.is_file():
        raise OclgiError(f"mesh file not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".zip":
        return _load_zip(path)
    if suffix == ".obj":
        return _from_obj(read_obj(path))
    if suffix in TRIMESH_TYPES:
        return _load_trimesh(path, path.read_bytes(), suffix)
    raise OclgiError(f"{path}: unsupported mesh type {suffix!r} (use one of {sorted(MESH_TYPES | {'.zip'})})")


def _from_obj(obj) -> LoadedMesh:
    names = [""] + obj.material_names
    return LoadedMesh(obj.vertices, obj.faces, obj.face_material + 1, names, obj.materials)


def _load_zip(path: Path) -> LoadedMesh:
    try:
        with zipfile.ZipFile(path) as z:
            members = [m for m in z.namelist() if Path(m).suffix.lower() in MESH_TYPES]
            if len(members) != 1:
                raise OclgiError(f"{path}: expected exactly one mesh file inside, found {len(members)}")
            inner = Path(members[0])
            data = z.read(members[0])
            if inner.suffix.lower() == ".obj":
                # material libraries are looked up beside the OBJ inside the zip
                names = set(z.namelist())

                def read_lib(name):
                    member = (inner.parent / name).as_posix()
                    if member not in names:
                        return None
                    return z.read(member).decode("utf-8", errors="replace")

                return _from_obj(read_obj(path / inner, data.decode("utf-8", errors="replace"), read_lib))
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, RuntimeError, EOFError) as exc:
        raise OclgiError(f"{path}: not a readable zip file ({exc})") from None
    return _load_trimesh(path, data, inner.suffix.lower())


def _load_trimesh(path: Path, data: bytes, suffix: str) -> LoadedMesh:
    import trimesh

    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=suffix[1:], process=False, force="scene")
    except Exception as exc:  # trimesh raises many types for malformed files
        raise OclgiError(f"{path}: cannot read {suffix[1:].upper()} file ({type(exc).__name__}: {exc})") from None
    verts, faces, fmat, names, mats = [], [], [], [""], {}
    offset = 0
    for name, geom in loaded.geometry.items():
        if not hasattr(geom, "faces") or len(geom.faces) == 0:
            continue
        # world transform of every node that instances this geometry
        nodes = loaded.graph.geometry_nodes.get(name, [None])
        for node in nodes:
            v = np.asarray(geom.vertices, dtype=np.float64)
            if node is not None:
                m, _ = loaded.graph[node]
                v = v @ m[:3, :3].T + m[:3, 3]
            verts.append(v)
            faces.append(np.asarray(geom.faces, dtype=np.int64) + offset)
            offset += len(v)
            mat = _trimesh_material(geom)
            if mat is not None:
                names.append(name)
                mats[name] = mat
                fmat.append(np.full(len(geom.faces), len(names) - 1))
            else:
                fmat.append(np.zeros(len(geom.faces), dtype=np.int64))
    if not faces:
        raise OclgiError(f"{path}: no faces")
    return LoadedMesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(fmat), names, mats)


def _trimesh_material(geom) -> MtlMaterial | None:
    mat = getattr(getattr(geom, "visual", None), "material", None)
    if mat is None or type(mat).__name__ != "PBRMaterial":
        return None
    albedo = emission = None
    if mat.baseColorFactor is not None:
        albedo = tuple(float(c) / 255.0 for c in np.asarray(mat.baseColorFactor)[:3])
    if mat.emissiveFactor is not None:
        emission = tuple(float(c) for c in np.asarray(mat.emissiveFactor)[:3])
    return MtlMaterial(albedo=albedo, emission=emission)
