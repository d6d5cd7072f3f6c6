"""A spec-following Wavefront OBJ/MTL reader.

trimesh mis-reads files that use relative (negative) face indices or a TAB
after ``v`` (McGuire's Cornell box among them: it loads 40 vertices, silently
wrong). This reader follows the format: any whitespace separates fields,
negative indices count back from the last vertex read so far, polygons are
fan-triangulated, ``usemtl`` names the material of the faces that follow and
``mtllib`` files give each material's ``Kd Ke Ks Ns Ni d Tr Tf illum`` and
texture names (``map_*``), which :func:`oclgi.scene.materials.from_file`
turns into a kind. ``vt`` and ``vn`` records (texture coordinates and
vertex normals, the second and third fields of ``v/vt/vn``) are read
per face corner, and only when asked for (``face_uv``, ``face_normal``). A material library that cannot be found is a warning
(its materials keep the defaults); a NaN or infinite vertex coordinate is an
error naming its line. A file without any ``usemtl`` takes its groups
(``g``) as the material names of their faces, each with the mesh's default
material until a scene file says otherwise.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import OclgiError
from .materials import FileMaterial
from .scene import OclgiWarning

_COLOURS = {"Kd": "albedo", "Ke": "emission", "Ks": "specular", "Tf": "transmission"}
_NUMBERS = {"Ns": "exponent", "Ni": "ior", "d": "dissolve"}


@dataclass
class ObjMesh:
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64, 0-based
    face_material: np.ndarray  # (F,) int64 index into material_names, -1 = none
    material_names: list[str] = field(default_factory=list)
    materials: dict[str, FileMaterial] = field(default_factory=dict)
    # () -> (F, 3, 2) texture coordinates, NaN where a face has none, or None
    # when the file has none: read when a texture needs them
    face_uv: Callable[[], np.ndarray | None] = lambda: None
    # () -> (F, 3, 3) vertex normals (vn) of the corners, NaN where a corner
    # has none, or None when the file has none: read when a mesh is smooth
    face_normal: Callable[[], np.ndarray | None] = lambda: None


def _plain(words) -> bool:
    """Python's int() and float() also read "0_2" (as 2), "1_000" and
    non-ASCII digits; the format has none of these. (Checked on the words
    joined: two string methods per line, not a pattern per number.)"""
    text = "".join(words)
    return text.isascii() and "_" not in text


def _floats(parts, path, lineno, n):
    try:
        if not _plain(parts[:n]):
            raise ValueError
        vals = [float(x) for x in parts[:n]]
    except ValueError:
        raise OclgiError(f"{path}:{lineno}: malformed number in {' '.join(parts)!r}") from None
    if len(vals) < n:
        raise OclgiError(f"{path}:{lineno}: expected {n} numbers, got {len(vals)}")
    return vals


def read_mtl(path: Path, text: str | None = None) -> dict[str, FileMaterial]:
    if text is None:
        try:
            text = path.read_text(errors="replace")
        except OSError as exc:
            raise OclgiError(f"cannot read material library {path}: {exc.strerror}") from None
    mats: dict[str, FileMaterial] = {}
    cur = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].split()
        if not line:
            continue
        key, args = line[0], line[1:]
        if key == "newmtl":
            name = " ".join(args)
            cur = mats.setdefault(name, FileMaterial())
        elif cur is None:
            continue
        elif key in _COLOURS:
            if args[:1] == ["spectral"] or args[:1] == ["xyz"]:
                raise OclgiError(f"{path}:{lineno}: {key} {args[0]} colours are not supported (give r g b)")
            vals = _floats(args, path, lineno, 1)
            if len(args) >= 3:
                vals = _floats(args, path, lineno, 3)
            else:
                vals = vals * 3
            setattr(cur, _COLOURS[key], tuple(vals))
        elif key in _NUMBERS:
            setattr(cur, _NUMBERS[key], _floats(args, path, lineno, 1)[0])
        elif key == "Tr":  # the complement of d
            cur.dissolve = 1.0 - _floats(args, path, lineno, 1)[0]
        elif key == "illum":
            value = _floats(args, path, lineno, 1)[0]
            if value != int(value):
                raise OclgiError(f"{path}:{lineno}: illum takes an integer, got {args[0]!r}")
            cur.illum = int(value)
        elif key.startswith("map_") or key in ("bump", "disp", "decal", "refl"):
            if args:
                cur.textures[key] = args[-1]  # options (-bm 1 ...) come first, the file name last
    return mats


def _lib_from_disk(path: Path) -> Callable[[str], str | None]:
    def read(name: str) -> str | None:
        lib = path.parent / name
        if not lib.is_file():
            return None
        try:
            return lib.read_text(errors="replace")
        except OSError as exc:
            raise OclgiError(f"cannot read material library {lib}: {exc.strerror}") from None
    return read


def read_obj(path: Path, text: str | None = None,
             read_lib: Callable[[str], str | None] | None = None) -> ObjMesh:
    """Read an OBJ file.

    ``text`` given: parse it instead of reading ``path``. ``read_lib(name)``
    returns the text of a material library named by ``mtllib`` or None when
    it does not exist; by default libraries are read next to ``path``.
    """
    path = Path(path)
    if read_lib is None:
        read_lib = _lib_from_disk(path)
    if text is None:
        try:
            text = path.read_text(errors="replace")
        except OSError as exc:
            raise OclgiError(f"cannot read {path}: {exc.strerror}") from None
    verts: list[list[float]] = []
    uvs: list[str] = []  # the vt records' lines
    vns: list[str] = []  # the vn records' lines
    faces: list[tuple[int, int, int]] = []
    face_lines: list = []  # faces with a v/vt/vn field: (line number, words, (vt, vn) so far, faces after it)
    face_mat: list[int] = []
    names: list[str] = []
    name_index: dict[str, int] = {}
    materials: dict[str, FileMaterial] = {}
    cur_mat = -1
    groups: list[str] = []
    group_index: dict[str, int] = {}
    face_group: list[int] = []
    cur_group = -1
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].split()
        if not line:
            continue
        key = line[0]
        if key == "v":
            xyz = _floats(line[1:], path, lineno, 3)
            if not all(math.isfinite(x) for x in xyz):
                raise OclgiError(f"{path}:{lineno}: vertex coordinate is NaN or infinite: {' '.join(line[1:4])!r}")
            verts.append(xyz)
        elif key == "vt":  # read only if a texture needs them (_corner_values)
            uvs.append(raw)  # a string: kept lists would slow the collector down (2-3x on Sponza)
        elif key == "vn":  # read only if a smooth mesh needs them
            vns.append(raw)
        elif key == "f":
            if len(line) < 4:
                raise OclgiError(f"{path}:{lineno}: a face needs at least 3 vertices")
            idx = []
            plain = _plain(line[1:])
            for tok in line[1:]:
                num = tok.split("/", 1)[0]
                try:
                    if not plain and not _plain([num]):
                        raise ValueError
                    k = int(num)
                except ValueError:
                    raise OclgiError(f"{path}:{lineno}: malformed face index {tok!r}") from None
                zero = k == 0  # OBJ counts from 1 (and back from -1): 0 and -0 name nothing
                if k < 0:
                    k = len(verts) + k  # relative: -1 is the last vertex read so far
                else:
                    k -= 1
                if zero or k < 0 or k >= len(verts):
                    raise OclgiError(f"{path}:{lineno}: face index {tok!r} refers to no vertex")
                idx.append(k)
            for j in range(1, len(idx) - 1):
                faces.append((idx[0], idx[j], idx[j + 1]))
                face_mat.append(cur_mat)
                face_group.append(cur_group)
            if "/" in line[1]:  # texture coordinates or normals, read at the end if needed
                face_lines.append((lineno, raw, (len(uvs), len(vns)), len(faces)))
        elif key == "g":  # a group: the material name of its faces when the file uses no usemtl
            group = " ".join(line[1:]) or "default"
            if group not in group_index:
                group_index[group] = len(groups)
                groups.append(group)
            cur_group = group_index[group]
        elif key == "usemtl":
            name = " ".join(line[1:])
            if name not in name_index:
                name_index[name] = len(names)
                names.append(name)
            cur_mat = name_index[name]
        elif key == "mtllib":
            # whitespace separates file names, unless the whole rest is one existing name
            whole = " ".join(line[1:])
            whole_text = read_lib(whole) if len(line) > 2 else None
            libs = [(whole, whole_text)] if whole_text is not None else [(n, read_lib(n)) for n in line[1:]]
            for lib, lib_text in libs:
                if lib_text is None:
                    warnings.warn(f"{path}:{lineno}: material library {lib!r} not found; "
                                  "its materials get the mesh's default albedo and emission",
                                  OclgiWarning, stacklevel=2)
                    continue
                materials.update(read_mtl(path.parent / lib, lib_text))
    if not faces:
        raise OclgiError(f"{path}: no faces")
    if not names and groups:
        # no usemtl at all (Sponza's OBJ): the groups name the faces' materials,
        # so a scene file can give each its own ([mesh.materials.floors])
        names, face_mat = groups, face_group
    def face_uv():
        return _corner_values(face_lines, uvs, _UV, len(faces), path) if uvs and face_lines else None

    def face_normal():
        return _corner_values(face_lines, vns, _NORMAL, len(faces), path) if vns and face_lines else None
    return ObjMesh(vertices=np.asarray(verts, dtype=np.float64).reshape(-1, 3),
                   faces=np.asarray(faces, dtype=np.int64).reshape(-1, 3),
                   face_material=np.asarray(face_mat, dtype=np.int64), material_names=names, materials=materials,
                   face_uv=face_uv, face_normal=face_normal)


@dataclass(frozen=True)
class _Corner:
    """What a face corner's field (v/vt/vn) names: its place in the field,
    the record's key and width, what it is called in errors."""
    field: int
    key: str
    width: int
    what: str


_UV = _Corner(1, "vt", 2, "texture coordinate")
_NORMAL = _Corner(2, "vn", 3, "normal")


def _corner_values(face_lines, records, kind: _Corner, n_faces: int, path) -> np.ndarray:
    """(F, 3, width) values of the fan-triangulated faces' corners (texture
    coordinates: vt's v defaults to 0; normals: vn x y z), NaN where a
    corner gives none."""
    corner = np.full((n_faces, 3), -1, np.int64)
    slot = 0 if kind is _UV else 1
    for lineno, raw, counts, end in face_lines:
        words = raw.split("#", 1)[0].split()
        plain = _plain(words[1:])
        idx = [_corner_index(f[kind.field], counts[slot], tok, path, lineno, plain, kind)
               if len(f) > kind.field and f[kind.field] else -1
               for tok in words[1:] for f in (tok.split("/"),)]
        first = end - (len(idx) - 2)
        for j in range(1, len(idx) - 1):
            corner[first + j - 1] = (idx[0], idx[j], idx[j + 1])
    table = np.full((len(records) + 1, kind.width), np.nan)  # the last row: a corner without one
    for k, raw in enumerate(records):
        words = raw.split("#", 1)[0].split()
        lineno = f"{kind.key} {k + 1}"  # the k-th record of its kind
        if kind is _UV:
            uv = _floats(words[1:], path, lineno, 1)
            table[k] = (uv[0], _floats(words[1:], path, lineno, 2)[1] if len(words) > 2 else 0.0)
        else:
            table[k] = _floats(words[1:], path, lineno, 3)
    return table[corner]


def _corner_index(text: str, n_records: int, tok: str, path, lineno: int, plain: bool, kind: _Corner) -> int:
    """A face corner's texture coordinate or normal index (the second or
    third field of v/vt/vn), 0-based."""
    try:
        if not plain and not _plain([text]):
            raise ValueError
        k = int(text)
    except ValueError:
        raise OclgiError(f"{path}:{lineno}: malformed {kind.what} index in {tok!r}") from None
    j = n_records + k if k < 0 else k - 1
    if k == 0 or j < 0 or j >= n_records:
        raise OclgiError(f"{path}:{lineno}: {tok!r} refers to no {kind.what} ({kind.key})")
    return j
