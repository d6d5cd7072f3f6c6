"""Scene descriptions: a TOML file, or the same structure as a Python dict.

    smooth = true                   # (before any table) the meshes' default for their own `smooth`

    [[mesh]]                        # one or more; a file, or inline arrays
    path = "cornell-box/CornellBox-Original.obj"   # relative to the TOML file
    albedo = [0.5, 0.5, 0.5]        # faces the file gives no material (default 0.5)
    emission = [0, 0, 0]
    material = { kind = "diffuse" } # or the kind and parameters of those faces (oclgi/scene/materials.py)
    transform = { scale = 1.0, rotate = [0, 1, 0, 30], translate = [0, 0, 0] }
    movable = false                 # true: an object of its own that Engine.move places
    smooth = true                   # shade with the file's vertex normals (OBJ vn, glTF/PLY normals)
    name = "bunny"                  # a movable object's name (default: the file's stem)
    [mesh.materials.light]          # override one material the file names
    emission = [17, 12, 4]
    [mesh.materials.glass]          # any kind and its parameters (oclgi/scene/materials.py)
    kind = "dielectric"
    ior = 1.5
    [mesh.materials.floor]
    texture = "floor.png"           # a diffuse albedo's texture, relative to the TOML file

    [[point_light]]
    position = [0, 1.9, 0]
    intensity = [1, 1, 1]           # W/sr (or candela = 100, colour = [1, 1, 1])
    # or: ies = "lamp.ies"          # an IES profile (scaled by candela or lumens; direction, c0 or matrix)

    [[spot_light]]
    position = [0, 1.9, 0]
    direction = [0, -1, 0]          # the axis it points along
    intensity = [5, 5, 5]           # W/sr on the axis (or candela, colour)
    cone_angle = 30                 # half-angle, degrees
    cone_delta = 5                  # falloff band inside the cone, degrees (smoothstep)

    [[sun]]
    direction = [0.3, -1, 0.2]      # the direction the light travels
    irradiance = [3, 3, 3]          # W/m^2 perpendicular to it (or lux, colour)

    [sky]
    radiance = [0.5, 0.6, 0.8]      # W/m^2/sr, uniform
    hemisphere = true               # from above the horizon only (false: every direction)
    up = [0, 1, 0]
    # or: map = "sky.exr"           # equirectangular radiance (+y at the top row), scale = 1.0

    [camera]
    position = [0, 1, 3.94]
    look_at = [0, 1, 0]
    up = [0, 1, 0]
    fov = 39.3                      # vertical, degrees
    width = 256
    height = 256

    [photons]
    count = 100000
    seed = 1
    max_depth = 16

    [estimator]
    method = "detp_disc_index"      # the default; detp (the plain oracle), detp_ray_map, ..., impact, photon_map
    radius = 0.04                   # disc radius; default 1% of the scene diagonal
    extension = 0.0                 # DETP extension e past the hit point
    count_emitted = true            # segments leaving the lights count (direct light)

oclgi/scene/lights.py has the lights' parameters, defaults and power,
oclgi/scene/light_tables.py the readers of their tables; a glTF mesh's
KHR_lights_punctual lights join them, placed by the mesh's transform
(oclgi/scene/gltf_lights.py). The readers of single values
(vectors, numbers, radiant values, keys) are oclgi/scene/values.py.

In the dict form a mesh may give ``vertices`` and ``faces`` arrays instead of
``path``. Unknown keys are errors, so a typo never passes silently.
"""

from __future__ import annotations

import math
import time
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import OclgiError
from .. import params
from .mesh import from_trimesh, is_file, load_mesh, transform_normals
from .materials import TABLE_KEYS, FileMaterial, from_file, from_table
from . import light_tables, lights as lights_mod
from .values import check_keys as _check_keys, number as _number, radiant as _radiant, table_list as _table_list
from .values import file_path, vec3 as _vec3
from .scene import MAX_COORDINATE, Camera, Material, Scene, SceneObject


_TOP = {"mesh", *lights_mod.TABLES, "camera", "photons", "estimator", "name", "smooth"}
_MESH = {"path", "vertices", "faces", "face_albedo", "face_emission", "vertex_albedo", "trimesh", "albedo",
         "emission", "material", "lumens", "materials", "transform", "movable", "name", "smooth"}
_CAMERA = {"position", "look_at", "up", "fov", "width", "height"}
# The run parameters a scene file sets: (table, key) -> RunParams field.
_SETTINGS = {("photons", "count"): "photons", ("photons", "seed"): "seed", ("photons", "max_depth"): "max_depth",
             ("estimator", "method"): "method", ("estimator", "radius"): "radius",
             ("estimator", "extension"): "extension", ("estimator", "count_emitted"): "count_emitted"}
_PHOTONS = {key for table, key in _SETTINGS if table == "photons"}
_ESTIMATOR = {key for table, key in _SETTINGS if table == "estimator"}


def load_file(path) -> Scene:
    t0 = time.perf_counter()
    path = Path(path)
    if not is_file(path, "scene file"):
        raise OclgiError(f"scene file not found: {path}")
    try:
        desc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise OclgiError(f"{path}: malformed TOML: {exc}") from None
    except UnicodeDecodeError:
        raise OclgiError(f"{path}: not a text (TOML) file") from None
    except RecursionError:  # tomllib recurses once per level of nested arrays or tables
        raise OclgiError(f"{path}: malformed TOML: arrays or tables nested too deeply") from None
    except OSError as exc:
        raise OclgiError(f"cannot read scene file {path}: {exc.strerror or exc}") from None
    desc.setdefault("name", path.stem)
    scene = load_dict(desc, base_dir=path.parent)
    scene.load_seconds = time.perf_counter() - t0
    return scene


class _Readers:
    """The readers a material table's values go through (materials.from_table);
    a texture's file name is relative to the scene file."""

    def __init__(self, base_dir):
        self.base_dir = base_dir

    vec3 = staticmethod(_vec3)
    radiant = staticmethod(_radiant)
    number = staticmethod(_number)

    def texture(self, value, where):
        from . import textures

        path = file_path(value, where, "an image file name", self.base_dir)
        if not is_file(path, "texture"):
            raise OclgiError(f"{where}: texture not found: {path}")
        return textures.read(path)


def _texture_reader(loaded, label):
    """Reads the texture a mesh file's material names or holds, or None."""
    from . import textures

    def read(value):
        if not isinstance(value, str):
            return textures.from_image(value, f"{label}: embedded texture")
        found = loaded.read_file(value) if getattr(loaded, "read_file", None) else None
        if isinstance(found, Path):  # on disk: read where it is, not copied through a temporary file
            return textures.read(found)
        return None if found is None else textures.read_bytes(found, value)
    return read


def _transform(t, where):
    _check_keys(t, {"scale", "rotate", "translate"}, where)
    m = np.eye(3)
    if "scale" in t:
        s = t["scale"]
        m = np.diag(_vec3(s, where + ".scale") if isinstance(s, (list, tuple)) else (_number(s, where + ".scale"),) * 3) @ m
    if "rotate" in t:
        r = t["rotate"]
        if not isinstance(r, (list, tuple)) or len(r) != 4:
            raise OclgiError(f"{where}.rotate: expected [axis x, y, z, degrees], got {r!r}")
        axis = np.asarray(_vec3(r[:3], where + ".rotate"))
        if np.linalg.norm(axis) == 0:
            raise OclgiError(f"{where}.rotate: zero axis")
        axis /= np.linalg.norm(axis)
        a = math.radians(_number(r[3], where + ".rotate"))
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        m = (np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * k @ k) @ m
    shift = np.asarray(_vec3(t["translate"], where + ".translate")) if "translate" in t else np.zeros(3)
    return m, shift


def _mesh(desc, i, base_dir, materials, lights=None, smooth=True):
    where = f"mesh[{i}]"
    _check_keys(desc, _MESH, where)
    per_element = [k for k in ("face_albedo", "face_emission", "vertex_albedo") if k in desc]
    if per_element and not ("vertices" in desc and "faces" in desc):
        raise OclgiError(f"{where}: {' and '.join(per_element)} go{'es' if len(per_element) == 1 else ''} with "
                         "'vertices' and 'faces'")
    smooth = _flag(desc.get("smooth", smooth), where + ".smooth")
    read = _Readers(base_dir)
    loaded = None
    # vertex_albedo is the albedo itself: the mesh's albedo (which multiplies it) is 1 unless given
    plain = (1.0, 1.0, 1.0) if "vertex_albedo" in desc else (0.5, 0.5, 0.5)
    default = Material(name=f"{where}.default", albedo=_vec3(desc.get("albedo", plain), where + ".albedo"),
                       emission=_radiant(desc.get("emission", (0, 0, 0)), where + ".emission"))
    if "material" in desc:  # the kind and parameters of the faces the file gives no material
        _check_keys(desc["material"], TABLE_KEYS, where + ".material")
        for key in ("albedo", "emission"):
            if key in desc and key in desc["material"]:
                raise OclgiError(f"{where}: give {key} in the mesh or in its material table, not both")
        default = from_table(where + ".material", desc["material"], default, read)
        default.name = f"{where}.default"
    overrides = desc.get("materials", {})
    if not isinstance(overrides, dict):
        raise OclgiError(f"{where}.materials: expected a table of material names, got {overrides!r}")
    file_lights = []  # a glTF's punctual lights (the other formats have none)
    if "path" in desc:  # a string, or a pathlib.Path from Python
        path = file_path(desc["path"], where + ".path", "a file name", base_dir)
        loaded = load_mesh(path)
        file_lights = loaded.lights  # a glTF's punctual lights
        label = path.name
    elif "trimesh" in desc:
        loaded = from_trimesh(desc["trimesh"], where + ".trimesh")
        label = desc.get("name", where)
    elif "vertices" in desc and "faces" in desc:
        vertices, faces = _inline_arrays(desc["vertices"], desc["faces"], where)
        fmat, names, file_mats = _face_materials(desc, len(faces), where)
        label = where
    else:
        raise OclgiError(f"{where}: give 'path', 'trimesh', or 'vertices' and 'faces'")
    if loaded is not None:
        vertices, faces, fmat, names, file_mats = (
            loaded.vertices, loaded.faces, loaded.face_material, loaded.names, loaded.materials)
    unknown = set(overrides) - set(names)
    if unknown:
        raise OclgiError(f"{where}.materials: {sorted(unknown)} not in the mesh's materials {sorted(n for n in names if n)}")
    # one scene material per material name of this mesh
    local = []
    texture_reader = _texture_reader(loaded, label)
    for name in names:
        if name == "":
            mat = default
        else:
            fm = file_mats.get(name)
            if fm is not None and fm.emission is not None:
                fm.emission = _radiant(fm.emission, f"{label}: material {name!r} (Ke)")
            # a table that sets the kind replaces the file's material: no warnings about it
            replaced = isinstance(overrides.get(name), dict) and "kind" in overrides[name]
            mat = from_file(f"{label}:{name}", fm, default, quiet=replaced, read_texture=texture_reader)
            if name in overrides:
                o = overrides[name]
                _check_keys(o, TABLE_KEYS, f"{where}.materials.{name}")
                mat = from_table(f"{where}.materials.{name}", o, mat, read)
        local.append(len(materials))
        materials.append(mat)
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise OclgiError(f"{label}: face indices out of range (0..{len(vertices) - 1} for "
                         f"{len(vertices)} vertices, found {faces.min()}..{faces.max()})")
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise OclgiError(f"{label}: {int(bad.sum())} vertices have NaN or infinite coordinates "
                         f"(the first is vertex {int(np.argmax(bad)) + 1})")
    face_colour = getattr(loaded, "face_colour", None)
    if "vertex_albedo" in desc:
        face_colour = _vertex_albedo(desc["vertex_albedo"], vertices, faces, where)
    m, shift = np.eye(3), np.zeros(3)
    if "transform" in desc:
        m, shift = _transform(desc["transform"], where + ".transform")
        vertices = vertices @ m.T + shift
    if file_lights and lights is not None:
        if _movable(desc, i):
            raise OclgiError(f"mesh[{i}]: {label} has lights (KHR_lights_punctual) and the mesh is movable; "
                             "moving lights are not supported yet")
        from .gltf_lights import transformed

        lights.extend(transformed(light, m, shift) for light in file_lights)
    if "lumens" in desc:  # every face of the mesh emits, its total luminous flux given
        from ..photometry import emission_from_lumens

        lumens = _number(desc["lumens"], where + ".lumens")
        if not lumens > 0:
            raise OclgiError(f"{where}.lumens: expected a luminous flux > 0, got {desc['lumens']!r}")
        v = vertices[faces]
        area = float(np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum() / 2)
        colour = desc.get("emission", (1.0, 1.0, 1.0))
        radiance = _radiant(emission_from_lumens(lumens, area, _vec3(colour, where + ".emission")),
                            where + ".lumens")
        for k in set(local):
            materials[k].emission = radiance
    if face_colour is not None:  # the mesh's diffuse materials take its vertex colours
        for k in set(local):
            materials[k].vertex_colours = materials[k].kind == "diffuse"
    textured = loaded is not None and any(materials[k].texture is not None for k in set(local))
    face_uv = loaded.face_uv() if textured else None  # read only when a texture needs them
    if textured and face_uv is None:
        raise OclgiError(f"{label}: a material has a texture but the mesh has no texture coordinates")
    camera = getattr(loaded, "camera", None)
    note = getattr(loaded, "camera_note", None)
    if camera is not None and "transform" in desc:  # the file's camera moves with its mesh
        camera = replace(camera, position=tuple(m @ np.asarray(camera.position) + shift),
                         look_at=tuple(m @ np.asarray(camera.look_at) + shift),
                         up=tuple(m @ np.asarray(camera.up)))
    # the file's vertex normals (kernels/shading_normals.h), read only for a smooth mesh
    face_normal = loaded.face_normal() if smooth and loaded is not None else None
    if face_normal is not None and "transform" in desc:
        face_normal = np.where(np.isnan(face_normal), np.nan, transform_normals(face_normal, m))
    return vertices, faces, np.asarray(local, dtype=np.int64)[fmat], face_uv, face_colour, (camera, note), face_normal


def _face_materials(desc, n_faces: int, where: str):
    """Per-face ``face_albedo`` / ``face_emission`` ((F, 3) arrays) as one
    material per distinct (albedo, emission) pair, named ``#0``, ``#1``, ...
    in order of first use; faces without them take the mesh's material."""
    per_face = {}
    for key in ("face_albedo", "face_emission"):
        if key in desc:
            a = np.asarray(desc[key])
            if a.shape != (n_faces, 3) or a.dtype.kind not in "iuf":
                raise OclgiError(f"{where}.{key}: expected an ({n_faces}, 3) array of numbers (one row per face), "
                                 f"got {a.dtype} {a.shape}")
            per_face[key] = a.astype(np.float64)
    if not per_face:
        return np.zeros(n_faces, np.int64), [""], {}
    cols = [per_face.get("face_albedo"), per_face.get("face_emission")]
    table = np.concatenate([c if c is not None else np.full((n_faces, 3), np.nan) for c in cols], axis=1)
    _, first, inverse = np.unique(table, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # materials numbered by first use, not by value
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    fmat = rank[inverse.ravel()] + 1
    names, mats = [""], {}
    for k, face in enumerate(first[order]):
        albedo = (tuple(_vec3([float(x) for x in table[face, :3]], f"{where}.face_albedo[{face}]"))
                  if cols[0] is not None else None)
        emission = tuple(float(x) for x in table[face, 3:]) if cols[1] is not None else None
        names.append(f"#{k}")
        mats[f"#{k}"] = FileMaterial(albedo=albedo, emission=emission)
    return fmat.astype(np.int64), names, mats


def _vertex_albedo(value, vertices, faces, where: str) -> np.ndarray:
    """``vertex_albedo`` ((V, 3) linear RGB in [0, 1]) as the (F, 3, 3) corner
    colours a glTF's COLOR_0 gives (the same device colour maps)."""
    a = np.asarray(value)
    if a.shape != (len(vertices), 3) or a.dtype.kind not in "iuf":
        raise OclgiError(f"{where}.vertex_albedo: expected an ({len(vertices)}, 3) array of numbers (one row per "
                         f"vertex), got {a.dtype} {a.shape}")
    a = a.astype(np.float64)
    bad = ~((a >= 0) & (a <= 1)).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise OclgiError(f"{where}.vertex_albedo[{k}]: an albedo is linear RGB from 0 to 1, got {a[k].tolist()}")
    return a[faces]


def _inline_arrays(vertices, faces, where):
    """A mesh given as ``vertices`` (V, 3) numbers and ``faces`` (F, 3) integer indices."""
    def rows(value, name):
        if isinstance(value, np.ndarray):  # the dict form: arrays pass as they are
            if value.ndim != 2 or value.shape[1] != 3 or value.dtype.kind not in "iuf":
                raise OclgiError(f"{where}.{name}: expected a ({name[0].upper()}, 3) array of numbers, "
                                 f"got {value.dtype} {value.shape}")
            return value.astype(np.float64)
        if not isinstance(value, (list, tuple)) or not all(
                isinstance(r, (list, tuple, np.ndarray)) and len(r) == 3 for r in value):
            raise OclgiError(f"{where}.{name}: expected a list of [a, b, c] rows")
        if any(isinstance(x, (bool, np.bool_)) for r in value for x in r):
            raise OclgiError(f"{where}.{name}: expected numbers only")
        try:
            return np.asarray(value, dtype=np.float64).reshape(-1, 3)
        except (TypeError, ValueError):
            raise OclgiError(f"{where}.{name}: expected numbers only") from None
        except OverflowError:  # an integer past float's range (TOML integers have any size)
            raise OclgiError(f"{where}.{name}: a number is too large (beyond 1e308)") from None

    v = rows(vertices, "vertices")
    f = rows(faces, "faces")
    if not len(v) or not len(f):
        raise OclgiError(f"{where}: vertices must be (V, 3) and faces (F, 3), both non-empty")
    if not np.isfinite(f).all() or (f != np.round(f)).any():
        raise OclgiError(f"{where}.faces: indices must be integers")
    return v, f.astype(np.int64)


def load_dict(desc: dict, base_dir=None) -> Scene:
    """Build a :class:`Scene` from a description dict (the TOML structure)."""
    _check_keys(desc, _TOP, "scene")
    base_dir = Path(base_dir) if base_dir is not None else None
    meshes = _table_list(desc.get("mesh", []), "mesh")
    if not meshes:
        raise OclgiError("scene: no [[mesh]] given")
    materials: list[Material] = []
    verts, faces, fmats, fobjs, offset = [], [], [], [], 0
    uvs, any_uv, colours, any_colour, normals, any_normal = [], False, [], False, [], False
    smooth = _flag(desc.get("smooth", True), "smooth")
    cameras = []  # the meshes' own (glTF) cameras
    # Static meshes form object 0; each movable mesh is an object of its own
    # (an instance with a transform over its own BVH). Triangles are stored
    # object by object, static first, so each object is one contiguous run.
    movable = [_movable(m, i) for i, m in enumerate(meshes)]
    order = [i for i in range(len(meshes)) if not movable[i]] + [i for i in range(len(meshes)) if movable[i]]
    objects: list[SceneObject] = []
    file_lights = []  # the meshes' own (glTF) lights
    for i in order:
        m = meshes[i]
        v, f, fm, uv, colour, file_camera, vn = _mesh(m, i, base_dir, materials, file_lights, smooth)
        cameras.append(file_camera)
        normals.append(vn if vn is not None else np.full((len(f), 3, 3), np.nan))
        any_normal = any_normal or vn is not None
        uvs.append(uv if uv is not None else np.full((len(f), 3, 2), np.nan))
        any_uv = any_uv or uv is not None
        colours.append(colour if colour is not None else np.full((len(f), 3, 3), np.nan))
        any_colour = any_colour or colour is not None
        if movable[i]:
            name = _object_name(m, i)
            if any(o.name == name for o in objects):
                raise OclgiError(f"mesh[{i}]: another movable mesh is already named {name!r}; give each a 'name'")
            objects.append(SceneObject(name, movable=True))
        elif not objects:
            objects.append(SceneObject("static", movable=False))
        verts.append(v)
        faces.append(f + offset)
        fmats.append(fm)
        fobjs.append(np.full(len(f), len(objects) - 1, np.int64))
        offset += len(v)

    point_lights, lights = light_tables.read(desc, base_dir)
    point_lights += [x for x in file_lights if isinstance(x, lights_mod.PointLight)]
    lights += [x for x in file_lights if not isinstance(x, lights_mod.PointLight)]

    camera, camera_note = None, None
    if "camera" in desc:
        c = desc["camera"]
        _check_keys(c, _CAMERA, "camera")
        if "position" not in c or "look_at" not in c:
            raise OclgiError("camera: 'position' and 'look_at' are required")
        camera = validate_camera(Camera(
            position=_vec3(c["position"], "camera.position", MAX_COORDINATE),
            look_at=_vec3(c["look_at"], "camera.look_at", MAX_COORDINATE),
            up=_vec3(c.get("up", (0, 1, 0)), "camera.up"), fov=_number(c.get("fov", 40.0), "camera.fov"),
            width=_number(c.get("width", 256), "camera.width", int),
            height=_number(c.get("height", 256), "camera.height", int)))
    elif any(c[0] is not None for c in cameras):  # none named: the first mesh's own (glTF, trimesh)
        camera, camera_note = next(c for c in cameras if c[0] is not None)
        camera = validate_camera(camera)

    tables = {"photons": desc.get("photons", {}), "estimator": desc.get("estimator", {})}
    _check_keys(tables["photons"], _PHOTONS, "photons")
    _check_keys(tables["estimator"], _ESTIMATOR, "estimator")
    given = {(t, k): field for (t, k), field in _SETTINGS.items() if k in tables[t]}
    settings = params.RunParams.read({field: tables[t][k] for (t, k), field in given.items()},
                                     names={field: f"{t}.{k}" for (t, k), field in given.items()})

    return Scene(vertices=np.concatenate(verts), faces=np.concatenate(faces), tri_material=np.concatenate(fmats),
                 materials=materials, tri_object=np.concatenate(fobjs),
                 tri_uv=np.concatenate(uvs) if any_uv else None,
                 tri_colour=np.concatenate(colours) if any_colour else None,
                 tri_vertex_normals=np.concatenate(normals) if any_normal else None,
                 objects=objects, point_lights=point_lights, lights=lights, camera=camera, camera_note=camera_note,
                 settings=settings, name=str(desc.get("name", "scene")))


def _flag(value, where) -> bool:
    if not isinstance(value, bool):
        raise OclgiError(f"{where}: expected true or false, got {value!r}")
    return value


def _movable(desc, i) -> bool:
    if not isinstance(desc, dict):
        return False  # _mesh reports the type error
    return _flag(desc.get("movable", False), f"mesh[{i}].movable")


def _object_name(desc, i) -> str:
    if "name" in desc:
        if not isinstance(desc["name"], str) or not desc["name"]:
            raise OclgiError(f"mesh[{i}].name: expected a non-empty string")
        return desc["name"]
    if "path" in desc and isinstance(desc["path"], str):
        return Path(desc["path"]).stem
    return f"mesh[{i}]"


def validate_camera(c: Camera) -> Camera:
    """``c`` checked as the device takes it (one check for the scene file's
    cameras, the API's and Mitsuba's), with its numbers as plain floats and ints."""
    vectors = {}
    for key in ("position", "look_at", "up"):  # a Camera made in Python has not been through _vec3
        v = getattr(c, key)
        try:
            a = np.asarray(v)
        except ValueError:
            a = np.asarray(None)
        if a.shape != (3,) or a.dtype.kind not in "iuf" or not (np.abs(a) <= MAX_COORDINATE).all():
            raise OclgiError(f"camera.{key}: expected 3 finite numbers, got {v!r}")
        vectors[key] = tuple(float(x) for x in a)
    fov = params.float32_real(c.fov, "camera.fov", 0.0, 180.0)
    if not (0 < fov < 180):
        raise OclgiError(f"camera.fov must be in (0, 180) degrees, got {fov}")
    c = replace(c, **vectors, fov=fov, width=params.image_size(c.width, "camera.width"),
                height=params.image_size(c.height, "camera.height"))
    fwd = np.subtract(c.look_at, c.position)
    if np.linalg.norm(fwd) == 0 or np.linalg.norm(np.cross(fwd, c.up)) == 0:
        raise OclgiError("camera: look_at must differ from position and not be along 'up'")
    return c
