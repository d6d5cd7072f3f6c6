"""Loading triangle meshes from files.

OBJ goes through oclgi's own reader (:mod:`oclgi.scene.obj`); PLY, glTF/GLB,
STL and OFF through trimesh. A ``.zip`` holding one mesh file is read in
memory (Sponza ships that way), within a bound on what it inflates to
(:mod:`oclgi.scene.zip_reader`); a glTF's buffers come from beside it, on
disk or in the zip. PLY and OFF headers are checked against their data
first (:mod:`oclgi.scene.counts`): trimesh reads a file whose counts lie
without a word. Every mesh comes back as float64 vertices,
int64 faces and one material name per face ('' when the file names none),
plus the materials the file itself defines.
"""

from __future__ import annotations

import io
import logging
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import interrupt
from ..errors import OclgiError
from .counts import check_counts
from .materials import FileMaterial
from .obj import read_obj
from .trimesh_errors import trimesh_problem
from .zip_reader import ZipReader

TRIMESH_TYPES = {".ply", ".glb", ".gltf", ".stl", ".off"}
MESH_TYPES = {".obj"} | TRIMESH_TYPES


@dataclass
class LoadedMesh:
    vertices: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray  # (F,) index into names
    names: list[str]
    materials: dict[str, FileMaterial]
    face_uv: object = lambda: None  # () -> (F, 3, 2) texture coordinates (NaN where a face has none) or None
    face_colour: np.ndarray | None = None  # (F, 3, 3) linear RGB of the corners (NaN where none), or None
    face_normal: object = lambda: None  # () -> (F, 3, 3) the file's vertex normals of the corners (NaN: none) or None
    read_file: object = None  # name -> Path, bytes (a zip member) or None: the files a material names (textures)
    lights: list = field(default_factory=list)  # a glTF's punctual lights (oclgi/scene/gltf_lights.py)
    camera: object = None  # a glTF's camera (gltf_lights.read_camera), or None
    camera_note: str | None = None  # said when ``camera`` is used: it is a default, not the file's own


def is_file(path: Path, what: str) -> bool:
    """``path.is_file()``, with the errors it raises (a name too long for
    the file system, a permission) as one line naming ``what`` it was."""
    try:
        return path.is_file()
    except OSError as exc:
        raise OclgiError(f"cannot read {what} {path}: {exc.strerror or exc}") from None


def load_mesh(path: Path) -> LoadedMesh:
    path = Path(path)
    if not is_file(path, "mesh file"):
        raise OclgiError(f"mesh file not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".zip":
        return _load_zip(path)
    if suffix == ".obj":
        return _from_obj(read_obj(path), _beside(path))
    if suffix in TRIMESH_TYPES:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise OclgiError(f"cannot read mesh file {path}: {exc.strerror or exc}") from None
        return _load_trimesh(path, data, suffix, lambda: _resolvers().FolderResolver(path))
    raise OclgiError(f"{path}: unsupported mesh type {suffix!r} (use one of {sorted(MESH_TYPES | {'.zip'})})")


def _from_obj(obj, read_file=None) -> LoadedMesh:
    names = [""] + obj.material_names
    return LoadedMesh(obj.vertices, obj.faces, obj.face_material + 1, names, obj.materials, face_uv=obj.face_uv,
                      face_normal=obj.face_normal, read_file=read_file)


def _beside(path: Path):
    """Finds the files a mesh's materials name, relative to its folder (the
    path, read where it is; a zip member's reader returns its bytes)."""
    def find(name: str):
        f = path.parent / name.replace("\\", "/")
        return f if is_file(f, "texture") else None
    return find


def _resolvers():
    """oclgi/scene/resolvers.py, which imports trimesh (half a second, so only
    for the files trimesh reads: OBJ has a reader of its own)."""
    from . import resolvers

    interrupt.reraise_swallowed()  # trimesh's imports swallow a Ctrl-C (oclgi/interrupt.py)
    return resolvers


def _load_zip(path: Path) -> LoadedMesh:
    try:
        with zipfile.ZipFile(path) as z:
            reader = ZipReader(path, z)
            members = [m for m in reader.names() if Path(m).suffix.lower() in MESH_TYPES]
            if len(members) != 1:
                raise OclgiError(f"{path}: expected exactly one mesh file inside, found {len(members)}")
            inner = Path(members[0])
            data = reader.read(members[0])
            if inner.suffix.lower() == ".obj":
                # material libraries are looked up beside the OBJ inside the zip
                names = set(reader.names())

                def read_lib(name):
                    member = (inner.parent / name).as_posix()
                    return reader.read(member).decode("utf-8", errors="replace") if member in names else None

                def read_member(name):
                    member = (inner.parent / name.replace("\\", "/")).as_posix()
                    return reader.read(member) if member in names else None

                return _from_obj(read_obj(path / inner, data.decode("utf-8", errors="replace"), read_lib), read_member)
            # a glTF's buffers and images are members beside it
            return _load_trimesh(path / inner, data, inner.suffix.lower(),
                                 lambda: _resolvers().MemberResolver(reader, inner.parent.as_posix()))
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, RuntimeError, EOFError,
            OSError, ValueError) as exc:
        raise OclgiError(f"{path}: not a readable zip file ({exc})") from None


def _load_trimesh(path: Path, data: bytes, suffix: str, resolver) -> LoadedMesh:
    """``data`` read by trimesh as a ``suffix`` file; ``resolver()`` gives
    the files it names (a glTF's ``.bin`` buffers), beside ``path``."""
    import trimesh

    kind = suffix[1:].upper()
    check_counts(path, data, suffix)
    files = resolver()
    # trimesh logs what it tries and fails on a malformed file, tracebacks
    # included; the user gets one line (below) instead
    log, hush = logging.getLogger("trimesh"), logging.NullHandler()
    log.addHandler(hush)
    propagate, log.propagate = log.propagate, False
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=suffix[1:], process=False, force="scene",
                              resolver=files)
    except OclgiError:
        raise
    except Exception as exc:  # trimesh raises many types for malformed files
        if files.refused is not None:
            raise files.refused from None
        raise OclgiError(f"{path}: cannot read {kind} file: {trimesh_problem(exc, files.missing)}") from None
    finally:
        log.removeHandler(hush)
        log.propagate = propagate
    mesh = from_trimesh(loaded, str(path))
    # a file's camera is its own or none (a scene file without [camera] says so when it renders),
    # never the default one a trimesh Scene given to the API gets
    mesh.camera, mesh.camera_note = None, None
    if suffix in (".gltf", ".glb"):
        from . import gltf_lights

        mesh.lights = gltf_lights.read(data, suffix, str(path))
        mesh.camera = gltf_lights.read_camera(data, suffix, str(path))
        from . import gltf_materials

        gltf_materials.apply(mesh.materials, gltf_materials.extensions(data, suffix))
    return mesh


def is_trimesh(obj) -> bool:
    """A trimesh ``Trimesh`` or ``Scene`` (told by type, without importing trimesh)."""
    return type(obj).__module__.startswith("trimesh.") and type(obj).__name__ in ("Trimesh", "Scene")


def from_trimesh(loaded, label: str) -> LoadedMesh:
    """A trimesh ``Scene`` (or ``Trimesh``) as oclgi's mesh: every
    geometry at each node that instances it, in world space, with its PBR
    material's base colour and emission (glTF's ``baseColorFactor`` and
    ``emissiveFactor``) where it has one."""
    if not is_trimesh(loaded):
        raise OclgiError(f"{label}: expected a trimesh Trimesh or Scene, got {type(loaded).__name__}")
    if type(loaded).__name__ == "Trimesh":
        import trimesh

        interrupt.reraise_swallowed()

        loaded = trimesh.Scene(loaded)
    path = label
    verts, faces, fmat, names, mats, uvs, colours, normals = [], [], [], [""], {}, [], [], []
    # glTF's COLOR_0 is linear; PLY's colours are 8-bit display (sRGB) values
    srgb = str(label).lower().endswith(".ply")
    offset = 0
    for name, geom in loaded.geometry.items():
        if not hasattr(geom, "faces") or len(geom.faces) == 0:
            continue
        f = np.asarray(geom.faces, dtype=np.int64)
        # checked per geometry: after the offset a -1 would name the previous one's last vertex
        if f.min() < 0 or f.max() >= len(geom.vertices):
            raise OclgiError(f"{path}: face indices out of range (0..{len(geom.vertices) - 1} for "
                             f"{len(geom.vertices)} vertices, found {f.min()}..{f.max()})")
        # world transform of every node that instances this geometry
        nodes = loaded.graph.geometry_nodes.get(name, [None])
        for node in nodes:
            v = np.asarray(geom.vertices, dtype=np.float64)
            vn = _file_normals(geom)
            if node is not None:
                m, _ = loaded.graph[node]
                v = v @ m[:3, :3].T + m[:3, 3]
                if vn is not None:
                    vn = transform_normals(vn, m[:3, :3])
            verts.append(v)
            normals.append(vn[f] if vn is not None else np.full((len(f), 3, 3), np.nan))
            faces.append(f + offset)
            offset += len(v)
            colours.append(_corner_colours(geom, f, srgb))
            uv = getattr(getattr(geom, "visual", None), "uv", None)
            uvs.append(np.asarray(uv, np.float64)[f] if uv is not None and len(uv) == len(geom.vertices)
                       else np.full((len(f), 3, 2), np.nan))
            mat = _trimesh_material(geom)
            if mat is not None:
                # named by the material (a scene file's [mesh.materials.NAME]), or by the
                # geometry when the material has no name; geometries sharing one share it
                key = _material_name(geom) or name
                if key not in mats:
                    names.append(key)
                    mats[key] = mat
                fmat.append(np.full(len(f), names.index(key)))
            else:
                fmat.append(np.zeros(len(f), dtype=np.int64))
    if not faces:
        raise OclgiError(f"{path}: no faces")
    face_uv = np.concatenate(uvs)
    face_colour = np.concatenate(colours) if any(not np.isnan(c).all() for c in colours) else None
    face_normal = np.concatenate(normals) if any(not np.isnan(n).all() for n in normals) else None
    camera, note = trimesh_camera(loaded)
    return LoadedMesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(fmat), names, mats,
                      lambda: face_uv, face_colour=face_colour, face_normal=lambda: face_normal,
                      camera=camera, camera_note=note)


TRIMESH_FOV = (60.0, 45.0)  # trimesh's default camera's field of view (x, y), degrees (Scene.set_camera)


def trimesh_camera(scene, height: int = 256):
    """A trimesh Scene's camera as an oclgi Camera (gltf_lights.camera_at),
    ``height`` pixels high at the camera's aspect ratio; and a note when it
    is trimesh's default camera (the one ``Scene.camera`` makes for a scene
    without one: everything in view, along -Z), else None. Computed without
    setting it on ``scene``."""
    from trimesh.scene import cameras

    from .gltf_lights import camera_at

    if scene.has_camera:
        world, fov, note = scene.camera_transform, np.asarray(scene.camera.fov, np.float64), None
    else:
        fov = np.asarray(TRIMESH_FOV)
        world = cameras.look_at(scene.bounds, fov=fov)
        note = ("the trimesh Scene has no camera: rendering from trimesh's default one (Scene.camera: "
                "everything in view, looking along -Z); give the scene a camera or a [camera] table to choose")
    if not (np.isfinite(fov).all() and (fov > 0).all() and (fov < 180).all()):
        return None, None  # nothing to look through: the scene's [camera] or the API's camera must say
    # trimesh keeps fov[0] / fov[1] as the image's aspect ratio (Camera.resolution from fov)
    aspect = math.tan(math.radians(fov[0]) / 2) / math.tan(math.radians(fov[1]) / 2)
    cam = camera_at(world, fov[1], aspect, height)
    return (cam, note) if cam is not None else (None, None)


def _file_normals(geom) -> np.ndarray | None:
    """(V, 3) the vertex normals a file gave (glTF NORMAL, PLY nx ny nz),
    or None. trimesh computes vertex normals from the faces when asked for
    ones it was not given, so only those in its cache before any question
    came from the file."""
    cache = getattr(getattr(geom, "_cache", None), "cache", {})
    if "vertex_normals" not in cache:
        return None
    vn = np.asarray(cache["vertex_normals"], np.float64)
    return vn if vn.shape == (len(geom.vertices), 3) else None


def transform_normals(normals: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Normals (..., 3) under the linear map m (3x3) of their points:
    through the inverse transpose, renormalised (right for scales and
    shears, not only rotations); a zero normal stays zero."""
    n = normals @ np.linalg.inv(m)  # (m^-T n) as rows: n^T m^-1
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def _corner_colours(geom, f, srgb: bool) -> np.ndarray:
    """(F, 3, 3) linear RGB at each face corner from trimesh's vertex or face
    colours, NaN when the geometry has none."""
    visual = getattr(geom, "visual", None)
    kind = getattr(visual, "kind", None)
    if kind == "vertex":
        c = np.asarray(visual.vertex_colors, np.float64)[:, :3] / 255.0
        corner = c[f]
    elif kind == "face":
        c = np.asarray(visual.face_colors, np.float64)[:, :3] / 255.0
        corner = np.repeat(c[:, None, :], 3, axis=1)
    else:
        return np.full((len(f), 3, 3), np.nan)
    if srgb:
        from .textures import srgb_to_linear

        corner = srgb_to_linear(corner)
    return corner


def _material_name(geom) -> str:
    mat = getattr(getattr(geom, "visual", None), "material", None)
    name = getattr(mat, "name", None)
    return name.strip() if isinstance(name, str) else ""


def _trimesh_material(geom) -> FileMaterial | None:
    """A glTF (or trimesh-made) PBR material's factors, textures named. A
    material without ``metallicFactor`` is read as non-metallic: glTF's
    default is 1, but a file (or a trimesh object) that gives none means a
    plain colour far more often than a metal."""
    mat = getattr(getattr(geom, "visual", None), "material", None)
    if mat is None or type(mat).__name__ != "PBRMaterial":
        return None
    fm = FileMaterial(source="gltf")
    if mat.baseColorFactor is not None:
        fm.albedo = tuple(float(c) / 255.0 for c in np.asarray(mat.baseColorFactor)[:3])
    if mat.emissiveFactor is not None:
        fm.emission = tuple(float(c) for c in np.asarray(mat.emissiveFactor)[:3])
    fm.metallic = 0.0 if mat.metallicFactor is None else float(mat.metallicFactor)
    if mat.roughnessFactor is not None:
        fm.roughness = float(mat.roughnessFactor)
    for key in ("baseColorTexture", "emissiveTexture", "metallicRoughnessTexture", "normalTexture"):
        if getattr(mat, key, None) is not None:
            fm.textures[key] = getattr(mat, key)  # an image trimesh decoded (PIL)
    return fm
