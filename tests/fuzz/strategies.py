"""Hypothesis strategies drawing fuzz cases, one per input format.

Each draws a :class:`fuzz.oracle.Case`: the files of a case folder (the
shipped Cornell box, ``scenes/cornell_box.toml`` and the mesh and material
library it references, with one of them mutated or replaced) and the command
that reads them. Most cases are near-valid, a shipped file with one to four
small changes, so that they get past the first check and reach the later
ones (and some reach the device); the rest are nasty: NaN, infinities, huge
and tiny numbers, wrong types, deep nesting, lying headers, truncated and
empty files, unicode.

Device work stays tiny: at most 2,000 photons, 8x8 images, a few points,
three frames, two seeds; a value that would make a valid run long (a million
frames) is never drawn, a value the engine must refuse (16385 pixels) is.
"""

from __future__ import annotations

import copy
import io
import tomllib
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from . import gltf_file, ply_file, toml_text
from .oracle import Case

SCENES = Path(__file__).resolve().parents[2] / "scenes"
BOX_OBJ = "cornell-box/CornellBox-Original.obj"
BOX_MTL = "cornell-box/CornellBox-Original.mtl"
METHODS = ("detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache", "impact", "photon_map")
MATERIALS = ("floor", "ceiling", "backWall", "rightWall", "leftWall", "shortBox", "tallBox", "light")


def _base_scene() -> dict:
    """cornell_box.toml, with a small camera and photon count, so that a
    case that drops the command line's limits still runs quickly, and one
    light of each other kind (oclgi/scene/lights.py), for their readers."""
    desc = tomllib.loads((SCENES / "cornell_box.toml").read_text())
    desc["camera"].update(width=8, height=8)
    desc["photons"]["count"] = 2000
    desc["spot_light"] = [{"position": [0.0, 1.9, 0.0], "direction": [0.0, -1.0, 0.0], "intensity": [1.0, 1.0, 1.0],
                           "cone_angle": 30.0, "cone_delta": 5.0}]
    desc["sun"] = [{"direction": [0.3, -1.0, 0.2], "irradiance": [1.0, 1.0, 1.0]}]
    desc["sky"] = {"radiance": [0.1, 0.1, 0.1], "hemisphere": True, "up": [0.0, 1.0, 0.0]}
    return desc


BASE = _base_scene()
CUBE_OBJ = b"""v -0.15 0 -0.15
v 0.15 0 -0.15
v 0.15 0 0.15
v -0.15 0 0.15
v -0.15 0.3 -0.15
v 0.15 0.3 -0.15
v 0.15 0.3 0.15
v -0.15 0.3 0.15
f 1 2 3 4
f 5 8 7 6
f 1 5 6 2
f 2 6 7 3
f 3 7 8 4
f 4 8 5 1
"""
# The command-line cases' scene: the Cornell box with a movable cube (animate needs one).
CLI_SCENE = toml_text.dumps({**BASE, "mesh": BASE["mesh"] + [
    {"path": "cube.obj", "name": "cube", "movable": True, "albedo": [0.7, 0.7, 0.7],
     "transform": {"translate": [0.3, 0.0, 0.2]}}]})


def cornell_files() -> dict:
    return {BOX_OBJ: (SCENES / BOX_OBJ).read_bytes(), BOX_MTL: (SCENES / BOX_MTL).read_bytes(),
            "scene.toml": toml_text.dumps(BASE).encode()}


def render_argv(scene="scene.toml") -> list:
    return ["render", scene, "--photons", "1000", "--width", "8", "--height", "8", "--quiet", "-o", "out/r.exr"]


# -- values -------------------------------------------------------------------------

NAN, INF = float("nan"), float("inf")
SPECIAL_FLOATS = [0.0, -0.0, 5e-324, 1e-320, 1.1e-38, 1.2e-38, 1e-19, 1e-18, 1e-9, 0.03, 0.5, 1.0, 2.0, 179.9,
                  180.0, 1e9, 1e18, 1e19, 3.4e38, 3.5e38, 1e300, 1.7976931348623157e308, NAN, INF, -INF,
                  -1.0, -1e-300]
SPECIAL_INTS = [0, 1, -1, 2, 3, 255, 256, 65535, 65536, 16384, 16385, 2**31 - 1, 2**31, 2**32, 2**53 + 1,
                2**63 - 1, 2**63, -2**63, 10**30, 10**400]
floats = st.one_of(st.sampled_from(SPECIAL_FLOATS), st.floats(), st.floats(-3, 3))
ints = st.one_of(st.sampled_from(SPECIAL_INTS), st.integers(-1000, 1000), st.integers())
numbers = st.one_of(floats, ints)
WORDS = ["", " ", "detp", "impact", "photon_map", "detp_disc_index", "nan", "inf", "1e5", "true",
         BOX_OBJ, "cornell-box", "missing.obj", "../scene.toml", ".", "\u00fcn\u00efc\u00f8d\u00e9",
         "\U0001f4a1", "a\x00b", "x" * 300, "light", "floor", "mesh[0]"]
texts = st.one_of(st.sampled_from(WORDS), st.text(st.characters(exclude_categories=("Cs",)), max_size=12))
scalars = st.one_of(numbers, st.booleans(), texts)
vec3 = st.one_of(st.lists(numbers, min_size=3, max_size=3), st.lists(st.floats(-2, 2), min_size=3, max_size=3),
                 st.lists(scalars, min_size=0, max_size=5))
KEYS = sorted({"mesh", "point_light", "camera", "photons", "estimator", "name", "path", "vertices", "faces",
               "albedo", "emission", "materials", "transform", "movable", "position", "look_at", "up", "fov",
               "width", "height", "count", "seed", "max_depth", "method", "radius", "extension",
               "count_emitted", "scale", "rotate", "translate", "intensity", "spot_light", "sun", "sky",
               "direction", "cone_angle", "cone_delta", "irradiance", "radiance", "hemisphere", "lux", "candela"})
keys = st.one_of(st.sampled_from(KEYS), texts)


def _rows(cell, min_size=0, max_size=6):
    return st.lists(st.lists(cell, min_size=3, max_size=3), min_size=min_size, max_size=max_size)


# A mesh given inline: a few triangles, now and then a nasty number or index.
inline_mesh = st.fixed_dictionaries(
    {"vertices": _rows(st.one_of(st.floats(-1, 2), st.floats(-1, 2), st.floats(-1, 2), numbers), 1),
     "faces": _rows(st.one_of(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3), ints), 1)},
    optional={"emission": st.one_of(st.lists(st.floats(0, 20), min_size=3, max_size=3), vec3),
              "albedo": st.one_of(st.lists(st.floats(0, 1), min_size=3, max_size=3), vec3),
              "movable": st.booleans()})
# Plausible values: what a user would write, or nearly.
plausible = st.one_of(
    st.sampled_from(METHODS), st.floats(-2, 2), st.integers(0, 300), st.booleans(),
    st.lists(st.floats(0, 1), min_size=3, max_size=3),
    st.fixed_dictionaries({}, optional={"scale": st.one_of(floats, vec3), "rotate": st.lists(numbers, max_size=5),
                                        "translate": vec3}),
    st.dictionaries(st.sampled_from(MATERIALS), st.fixed_dictionaries(
        {}, optional={"albedo": vec3, "emission": vec3}), max_size=2),
    inline_mesh,
)
toml_values = st.recursive(st.one_of(scalars, vec3, plausible),
                           lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                   st.dictionaries(keys, inner, max_size=3)),
                           max_leaves=8)


def _npy_bytes(a, **kw) -> bytes:
    """``a`` as the bytes of a .npy file."""
    buf = io.BytesIO()
    np.save(buf, a, **kw)
    return buf.getvalue()


def _deep_list(depth: int):
    v = 1
    for _ in range(depth):
        v = [v]
    return v


def _array(dtype, shape, fill):
    if dtype == "U3":
        return np.full(shape, "ab")
    with np.errstate(all="ignore"):  # NaN or 2^40 cast to a small integer type: the nasty value sought
        return np.full(shape, fill).astype(dtype)


numpy_arrays = st.builds(
    _array,
    st.sampled_from(["float64", "float32", "float16", "int64", "int8", "uint8", "bool", "complex128", "U3",
                     "object"]),
    st.sampled_from([(3, 3), (4, 3), (0, 3), (3,), (3, 2), (2, 3, 1), (), (1, 3)]),
    st.sampled_from([0, 1, 2, -1, 0.5, NAN, INF, 1e300, 2**40]))
dict_scalars = st.one_of(
    scalars, st.none(), st.binary(max_size=6), st.complex_numbers(max_magnitude=10),
    st.sampled_from([np.float64(NAN), np.float32(1.5), np.int64(3), np.bool_(True), np.uint8(255),
                     Path(BOX_OBJ), (1, 2, 3), frozenset({1}), b"cornell-box/CornellBox-Original.obj"]),
    numpy_arrays, st.integers(1, 400).map(_deep_list))
dict_values = st.recursive(st.one_of(dict_scalars, vec3, plausible),
                           lambda inner: st.one_of(st.lists(inner, max_size=4), st.tuples(inner, inner, inner),
                                                   st.dictionaries(st.one_of(keys, ints), inner, max_size=3)),
                           max_leaves=8)


# -- scene descriptions ---------------------------------------------------------------


def _slots(obj):
    """Every (container, key) of a description, nested tables and arrays included."""
    if isinstance(obj, dict):
        items = list(obj.items())
    elif isinstance(obj, list):
        items = list(enumerate(obj))
    else:
        return
    for k, v in items:
        yield obj, k
        yield from _slots(v)


def _scaled(value, factor):
    """value * factor in value's type (an int too large for a float stays as it is)."""
    try:
        return type(value)(value * factor)
    except (OverflowError, ValueError):
        return value


@st.composite
def tweak(draw, value):
    """A value near ``value``: a number scaled, negated or made nasty, one
    component of a vector changed, a word retyped."""
    if isinstance(value, bool):
        return draw(st.sampled_from([not value, 0, 1, "true"]))
    if isinstance(value, (int, float)):
        return draw(st.one_of(st.floats(0.1, 10).map(lambda f: _scaled(value, f)), st.just(-value),
                              st.just(_scaled(value, 1.0)), floats, ints))
    if isinstance(value, str):
        return draw(st.one_of(st.sampled_from(METHODS), st.just(value.upper()), st.just(value + " "),
                              st.just(value[:-1]), texts))
    if isinstance(value, list) and value:
        value = list(value)
        i = draw(st.integers(0, len(value) - 1))
        op = draw(st.sampled_from(["set", "set", "drop", "add"]))
        if op == "set":
            value[i] = draw(tweak(value[i]))
        elif op == "drop":
            del value[i]
        else:
            value.append(draw(numbers))
        return value
    if isinstance(value, dict) and value:
        value = dict(value)
        k = draw(st.sampled_from(sorted(value, key=str)))
        value[k] = draw(tweak(value[k]))
        return value
    return draw(toml_values)


@st.composite
def mutated_desc(draw, values, base=BASE):
    desc = copy.deepcopy(base)
    for _ in range(draw(st.sampled_from([1, 1, 1, 2, 3]))):
        slots = list(_slots(desc))
        op = draw(st.sampled_from(["tweak", "tweak", "tweak", "tweak", "set", "delete", "add", "wrap", "mesh"]))
        if op == "tweak" and slots:
            container, k = draw(st.sampled_from(slots))
            container[k] = draw(tweak(container[k]))
        elif op == "mesh" and isinstance(desc.get("mesh"), list):
            desc["mesh"].append(draw(inline_mesh))
        elif op == "add" or not slots:
            tables = [desc] + [c[k] for c, k in slots if isinstance(c[k], dict)]
            draw(st.sampled_from(tables))[draw(keys)] = draw(values)
        else:
            container, k = draw(st.sampled_from(slots))
            if op == "set":
                container[k] = draw(values)
            elif op == "delete":
                del container[k]
            else:
                container[k] = [container[k]]
    return desc


@st.composite
def text_mutation(draw, text: str) -> bytes:
    """The text as it is (most often), or broken the way files break."""
    op = draw(st.sampled_from(["none"] * 8 + ["truncate", "insert", "delete_line", "dup_line", "deep", "bytes",
                                              "empty", "crlf"]))
    data = text.encode("utf-8", "surrogatepass")
    lines = text.splitlines(keepends=True)
    if op == "truncate":
        return data[:draw(st.integers(0, max(0, len(data) - 1)))]
    if op == "insert":
        at = draw(st.integers(0, len(text)))
        return (text[:at] + draw(texts) + text[at:]).encode("utf-8", "surrogatepass")
    if op in ("delete_line", "dup_line") and lines:
        i = draw(st.integers(0, len(lines) - 1))
        lines[i:i + 1] = [] if op == "delete_line" else [lines[i], lines[i]]
        return "".join(lines).encode("utf-8", "surrogatepass")
    if op == "deep":
        depth = draw(st.sampled_from([50, 500, 1000, 3000, 100000]))
        kind = draw(st.sampled_from(["array", "table"]))
        deep = "[" * depth + "1" + "]" * depth if kind == "array" else "{a = " * depth + "1" + "}" * depth
        if draw(st.booleans()):
            return f"fov = {deep}\n".encode() + data
        return data.replace(b"fov = ", f"fov = {deep}\n#".encode(), 1)
    if op == "bytes":
        at = draw(st.integers(0, len(data)))
        return data[:at] + draw(st.binary(min_size=1, max_size=8)) + data[at:]
    if op == "empty":
        return b""
    if op == "crlf":
        return data.replace(b"\n", draw(st.sampled_from([b"\r\n", b"\r"])))
    return data


@st.composite
def toml_cases(draw):
    """A mutated cornell_box.toml, rendered."""
    desc = draw(mutated_desc(toml_values))
    files = cornell_files()
    files["scene.toml"] = draw(text_mutation(toml_text.dumps(desc)))
    return Case("toml", files, render_argv())


@st.composite
def dict_cases(draw):
    """A mutated Cornell box description for oclgi.load_dict, Python values of any type included."""
    desc = draw(mutated_desc(dict_values))
    files = cornell_files()
    del files["scene.toml"]
    return Case("dict", files, None, desc)


# -- OBJ and MTL ----------------------------------------------------------------------

NUMBER_WORDS = ["nan", "-nan", "inf", "-inf", "1e400", "-1e400", "1e-400", "0", "-0", "1e17", "1e18", "1e19",
                "1e38", "3.4e38", "0x10", "1_0", "+.5", ".", "e5", "\u0661", "\uff11", "1,5", "", "--1", "1e",
                "5e-324", "0.5", "2", "-1"]
number_words = st.one_of(st.sampled_from(NUMBER_WORDS), floats.map(repr), st.integers(-10, 10).map(str))
INDEX_WORDS = ["0", "-0", "1", "-1", "2", "-2", "8", "9", "-9", "36", "37", "1/1", "1//1", "1/2/3", "//",
               "a", "1.5", "2147483648", "-2147483649", "9223372036854775808", "1e3", "\u0661", "", "1/"]
index_words = st.one_of(st.sampled_from(INDEX_WORDS), ints.map(str))
NAME_WORDS = ["CornellBox-Original.mtl", "missing.mtl", ".", "..", "../cornell-box/CornellBox-Original.mtl",
              "CornellBox-Original.mtl CornellBox-Original.mtl", "\u00fcn\u00efc\u00f8d\u00e9.mtl", "light",
              "floor", "", "x" * 300]
names = st.one_of(st.sampled_from(NAME_WORDS), texts)
obj_lines = st.one_of(
    st.builds(lambda xs: "v " + " ".join(xs), st.lists(number_words, max_size=5)),
    st.builds(lambda xs: "f " + " ".join(xs), st.lists(index_words, max_size=6)),
    st.builds(lambda n: "f " + " ".join(str(i) for i in range(1, n + 1)), st.sampled_from([3, 36, 37, 2000])),
    st.builds(lambda k, n: f"{k} {n}", st.sampled_from(["usemtl", "mtllib", "o", "g", "s"]), names),
    st.sampled_from(["vt 0 0", "vn 0 1 0", "l 1 2", "p 1", "s off", "usemtl", "mtllib", "f", "v", "#",
                     "\\", "x" * 100000, "v 0 0 0 1 1 1", "f 1 2 3 # c"]),
    texts)
MTL_LINES = st.one_of(
    st.builds(lambda k, xs: k + " " + " ".join(xs), st.sampled_from(["Kd", "Ke", "Ka", "Ns", "d", "illum"]),
              st.lists(number_words, max_size=4)),
    st.builds(lambda n: f"newmtl {n}", names),
    st.sampled_from(["newmtl", "Kd", "Ke", "Ke spectral file.rfl", "Kd xyz 1 1 1", "map_Kd tex.png"]),
    texts)


@st.composite
def line_mutation(draw, data: bytes, new_lines) -> bytes:
    """One to four changes to a text file, line by line: a token replaced or
    dropped, a line deleted, doubled or added; or the file truncated, given
    other line ends, a byte that is no UTF-8, or emptied."""
    lines = data.decode().splitlines()
    whole = None
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["token", "token", "drop", "delete", "dup", "insert", "insert", "whole"]))
        i = draw(st.integers(0, max(0, len(lines) - 1)))
        parts = lines[i].split() if lines else []
        if op == "token" and len(parts) > 1:
            j = draw(st.integers(1, len(parts) - 1))
            word = number_words if parts[0] in ("v", "Kd", "Ke", "Ka") else index_words if parts[0] == "f" else names
            parts[j] = draw(word)
            lines[i] = " ".join(parts)
        elif op == "drop" and parts:
            lines[i] = " ".join(parts[:-1])
        elif op == "delete" and lines:
            del lines[i]
        elif op == "dup" and lines:
            lines.insert(i, lines[i])
        elif op == "whole":
            whole = draw(st.sampled_from(["truncate", "cr", "crlf", "badbyte", "empty", "nul"]))
        else:
            lines.insert(i, draw(new_lines))
    out = ("\n".join(lines) + "\n").encode("utf-8", "surrogatepass")
    if whole == "truncate":
        out = out[:draw(st.integers(0, len(out)))]
    elif whole == "cr":
        out = out.replace(b"\n", b"\r")
    elif whole == "crlf":
        out = out.replace(b"\n", b"\r\n")
    elif whole == "badbyte":
        at = draw(st.integers(0, len(out)))
        out = out[:at] + b"\xff\xfe" + out[at:]
    elif whole == "empty":
        out = b""
    elif whole == "nul":
        out = out.replace(b" ", b"\0", 3)
    return out


@st.composite
def line_cases(draw, fmt, member, new_lines):
    """The Cornell box with ``member`` (its OBJ or MTL file) mutated line by line, rendered."""
    files = cornell_files()
    files[member] = draw(line_mutation(files[member], new_lines))
    return Case(fmt, files, render_argv())


# -- meshes for trimesh: PLY, glTF, GLB ---------------------------------------------------


@st.composite
def small_mesh(draw):
    """A few triangles inside the box, some values made nasty."""
    n = draw(st.integers(3, 10))
    verts = draw(st.lists(st.lists(st.floats(-0.9, 0.9), min_size=3, max_size=3), min_size=n, max_size=n))
    verts = [[x, abs(y) + 0.05, z] for x, y, z in verts]
    faces = draw(st.lists(st.lists(st.integers(0, n - 1), min_size=3, max_size=3), min_size=1, max_size=8))
    for _ in range(draw(st.integers(0, 3))):
        what = draw(st.sampled_from(["coord", "index", "size"]))
        if what == "coord":
            verts[draw(st.integers(0, n - 1))][draw(st.integers(0, 2))] = draw(floats)
        elif what == "index":
            face = faces[draw(st.integers(0, len(faces) - 1))]
            if face:
                face[draw(st.integers(0, len(face) - 1))] = draw(ints)
        else:
            faces[draw(st.integers(0, len(faces) - 1))] = draw(st.lists(st.integers(-1, n), max_size=6))
    return verts, faces


def _mesh_scene(name: str, extra: dict) -> bytes:
    return toml_text.dumps({**BASE, "mesh": BASE["mesh"] + [{"path": name, **extra}]}).encode()


mesh_options = st.fixed_dictionaries({}, optional={"emission": st.one_of(
    st.lists(st.floats(0, 10), min_size=3, max_size=3), st.lists(st.floats(0, 10), min_size=3, max_size=3), vec3),
                                                   "albedo": st.lists(st.floats(0, 1), min_size=3, max_size=3),
                                                   "movable": st.booleans(),
                                                   "transform": st.fixed_dictionaries({}, optional={"scale": floats})})


@st.composite
def ply_cases(draw):
    files = cornell_files()
    if draw(st.integers(0, 19)) == 0:  # now and then the shipped bunny, cut short
        bunny = (SCENES / "stanford-bunny/bun_zipper.ply").read_bytes()
        data = bunny[:draw(st.integers(0, len(bunny)))]
        extra = {"transform": {"scale": 4.0, "translate": [0, 0, 0]}}
    else:
        verts, faces = draw(small_mesh())
        fmt = draw(st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian", "ascii",
                                    "binary_middle_endian"]))
        vtype = draw(st.sampled_from(["float", "float", "double", "float32", "int", "uchar", "float128"]))
        itypes = draw(st.sampled_from([("uchar", "int"), ("uchar", "int"), ("uchar", "uint"), ("int", "int"),
                                       ("uchar", "ushort"), ("uchar", "float"), ("char", "char")]))
        lie = st.one_of(st.none(), st.none(), st.none(), st.none(), st.sampled_from([0, -1, 2**31, 2**63, 10**20]),
                        st.integers(0, 20))
        header = draw(st.lists(st.sampled_from(["comment \u00fcn\u00efc\u00f8d\u00e9", "obj_info x",
                                                "element normal 5", "property float nx", "element vertex 3",
                                                "format ascii 1.0", "end_header", "ply"]), max_size=2))
        truncate = draw(st.one_of(st.none(), st.none(), st.floats(0, 1)))
        data = ply_file.write(fmt, vtype, itypes, verts, faces, draw(lie), draw(lie), header, truncate)
        extra = draw(mesh_options)
    files["m.ply"] = data
    files["scene.toml"] = _mesh_scene("m.ply", extra)
    return Case("ply", files, render_argv())


json_values = st.recursive(st.one_of(st.none(), st.booleans(), numbers, texts),
                           lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                   st.dictionaries(texts, inner, max_size=3)), max_leaves=5)
GLTF_EDITS = [
    (("accessors", 0, "count"), st.one_of(st.integers(-2, 100), st.sampled_from([2**31, 2**32 + 3]))),
    (("accessors", 1, "count"), st.one_of(st.integers(-2, 100), st.sampled_from([2**31, 2**32 + 3]))),
    (("accessors", 1, "componentType"), st.sampled_from([5120, 5121, 5122, 5123, 5125, 5126, 0, 9999])),
    (("accessors", 0, "componentType"), st.sampled_from([5120, 5121, 5122, 5123, 5125, 5126, 0])),
    (("accessors", 0, "type"), st.sampled_from(["SCALAR", "VEC2", "VEC4", "MAT4", "X", ""])),
    (("accessors", 1, "type"), st.sampled_from(["VEC3", "VEC2", "MAT4", "X"])),
    (("bufferViews", 0, "byteOffset"), st.one_of(st.integers(-8, 400), st.sampled_from([2**40]))),
    (("bufferViews", 1, "byteOffset"), st.one_of(st.integers(-8, 400), st.sampled_from([2**40]))),
    (("bufferViews", 0, "byteStride"), st.sampled_from([0, 1, 4, 12, 13, 256, -4])),
    (("bufferViews", 1, "byteLength"), st.integers(-4, 1000)),
    (("buffers", 0, "byteLength"), st.integers(-4, 1000)),
    (("buffers", 0, "uri"), st.sampled_from(["missing.bin", "../scene.toml", "data:,", "", "cornell-box",
                                             "data:application/octet-stream;base64,@@@",
                                             "http://example.invalid/x.bin"])),
    (("nodes", 0, "matrix"), st.lists(floats, min_size=0, max_size=17)),
    (("nodes", 0, "scale"), st.lists(floats, min_size=3, max_size=3)),
    (("nodes", 0, "children"), st.sampled_from([[0], [1], [-1], [0, 0]])),
    (("nodes", 0, "mesh"), st.sampled_from([1, -1, None, "0"])),
    (("scenes", 0, "nodes"), st.sampled_from([[1], [-1], [], [0, 0], None])),
    (("scene",), st.sampled_from([1, -1, None, "0"])),
    (("meshes", 0, "primitives", 0, "mode"), st.sampled_from([0, 1, 2, 3, 5, 6, 7, -1])),
    (("meshes", 0, "primitives", 0, "indices"), st.sampled_from([0, 2, -1, None])),
    (("meshes", 0, "primitives", 0, "material"), st.sampled_from([1, -1, None])),
    (("materials", 0, "pbrMetallicRoughness", "baseColorFactor"), st.lists(floats, max_size=5)),
    (("materials", 0, "emissiveFactor"), st.lists(floats, max_size=4)),
    (("extensionsRequired",), st.sampled_from([["KHR_draco_mesh_compression"], ["EXT_nope"], "x"])),
    (("asset", "version"), st.sampled_from(["1.0", "3.0", "", None])),
]


def _set_path(doc, path, value):
    """Set doc[p0][p1]...; a path through something that is no container is left alone."""
    node = doc
    for p in path[:-1]:
        try:
            node = node[p]
        except (KeyError, IndexError, TypeError):
            return
    try:
        node[path[-1]] = value
    except (IndexError, TypeError):
        pass


@st.composite
def gltf_cases(draw):
    files = cornell_files()
    verts, faces = draw(small_mesh())
    flat = [i for f in faces for i in f]
    doc, blob = gltf_file.document(verts, flat, draw(st.sampled_from([5125, 5125, 5123, 5121])),
                                   base_color=draw(st.lists(st.floats(0, 1), min_size=4, max_size=4)),
                                   emissive=draw(st.sampled_from([(0, 0, 0), (0, 0, 0), (5, 5, 5), (1, 1, 1)])))
    for _ in range(draw(st.sampled_from([0, 0, 1, 1, 2, 3]))):
        if draw(st.integers(0, 4)) == 0:  # anywhere in the document
            slots = list(_slots(doc))
            container, k = draw(st.sampled_from(slots))
            if draw(st.booleans()):
                container[k] = draw(json_values)
            else:
                del container[k]
        else:
            path, values = draw(st.sampled_from(GLTF_EDITS))
            _set_path(doc, path, draw(values))
    binary = draw(st.booleans())
    if binary:
        lie = st.one_of(st.just(0), st.just(0), st.integers(-40, 40), st.sampled_from([2**31, -12]))
        data = gltf_file.glb(doc, blob, draw(lie), draw(lie))
        name = "m.glb"
    else:
        data = gltf_file.gltf(doc, blob)
        name = "m.gltf"
    if draw(st.integers(0, 4)) == 0:
        data = data[:draw(st.integers(0, len(data)))]
    files[name] = data
    files["scene.toml"] = _mesh_scene(name, draw(mesh_options))
    return Case("gltf", files, render_argv())


# -- points files ---------------------------------------------------------------------

point_rows = st.lists(st.tuples(st.floats(-0.9, 0.9), st.floats(0.01, 1.9), st.floats(-0.9, 0.9),
                                st.sampled_from([(0, 1, 0), (0, -1, 0), (1, 0, 0), (0, 0, 1), (0.3, 0.3, 0.3)])
                                ).map(lambda r: [r[0], r[1], r[2], *r[3]]), min_size=1, max_size=12)
CSV_CELLS = NUMBER_WORDS + ["x", "nx", "E_r", " ", "1 2", '"1"', "1;2", "\u00fcn\u00efc\u00f8d\u00e9"]
HEADERS = ["x,y,z,nx,ny,nz", "x y z nx ny nz", "# points", "", "x,y,1,2,3,4", "\ufeffx,y,z,nx,ny,nz",
           "x,y,z", "a,b,c,d,e,f,g"]


@st.composite
def csv_points(draw) -> bytes:
    rows = [[repr(float(x)) for x in r] for r in draw(point_rows)]
    for _ in range(draw(st.integers(0, 3))):
        i = draw(st.integers(0, len(rows) - 1))
        op = draw(st.sampled_from(["cell", "cell", "row", "short", "long"]))
        if op == "cell" and rows[i]:
            rows[i][draw(st.integers(0, len(rows[i]) - 1))] = draw(st.one_of(st.sampled_from(CSV_CELLS),
                                                                            floats.map(repr)))
        elif op == "row":
            rows[i] = draw(st.lists(st.sampled_from(CSV_CELLS), max_size=8))
        elif op == "short" and rows[i]:
            rows[i] = rows[i][:-1]
        elif op == "long":
            rows[i] = rows[i] + ["0"]
    sep = draw(st.sampled_from([",", ",", " ", "\t", ", ", ";"]))
    header = draw(st.one_of(st.none(), st.sampled_from(HEADERS)))
    lines = ([header] if header is not None else []) + [sep.join(r) for r in rows]
    if draw(st.booleans()):
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(["", "# c", "  ", ",,,,,"])))
    text = (draw(st.sampled_from(["\n", "\r\n"])).join(lines)).encode("utf-8", "surrogatepass")
    return draw(st.sampled_from([text, text, text, text[:len(text) // 2], b"", b"\xff\xfe" + text]))


@st.composite
def npy_points(draw) -> bytes:
    rows = draw(point_rows)
    a = np.array(rows, dtype=np.float64)
    op = draw(st.sampled_from(["none", "none", "dtype", "shape", "value", "zero_normal"]))
    if op == "dtype":
        a = a.astype(draw(st.sampled_from(["float32", "float16", "int64", "uint8", "bool", "complex128", ">f8",
                                           "U8", "object", "datetime64[s]"])))
    elif op == "shape":
        a = draw(st.sampled_from([a[:, :5], np.hstack([a, a[:, :1]]), a.reshape(-1), a[:0], a[None],
                                  np.float64(1.0), np.asfortranarray(a), a.reshape(-1, 6, 1)]))
    elif op == "value":
        a[draw(st.integers(0, len(a) - 1)), draw(st.integers(0, 5))] = draw(floats)
    elif op == "zero_normal":
        a[draw(st.integers(0, len(a) - 1)), 3:] = 0
    data = _npy_bytes(a, allow_pickle=True)
    edit = draw(st.sampled_from(["none", "none", "none", "truncate", "magic", "version", "header", "shape"]))
    if edit == "truncate":
        data = data[:draw(st.integers(0, len(data)))]
    elif edit == "magic":
        data = b"\x93NUMPX" + data[6:]
    elif edit == "version":
        data = data[:6] + bytes([draw(st.sampled_from([0, 3, 99])), 0]) + data[8:]
    elif edit == "header":
        data = data[:8] + draw(st.binary(min_size=2, max_size=2)) + data[10:]
    elif edit == "shape":
        shape = draw(st.sampled_from([b"(300000000000, 6)", b"(-1, 6)", b"(2, 6)", b"(100, 6)", b"(1, 6, 2)",
                                      b"(1e3, 6)", b"[1, 6]"]))
        head_len = int.from_bytes(data[8:10], "little")
        head = data[10:10 + head_len]
        start = head.find(b"'shape': ") + len(b"'shape': ")
        end = head.find(b")", start) + 1
        new = head[:start] + shape + head[end:]
        new = new.rstrip(b"\n ").ljust(head_len - 1)[:head_len - 1] + b"\n"
        data = data[:10] + new + data[10 + head_len:]
    return data


@st.composite
def points_cases(draw):
    files = cornell_files()
    kind = draw(st.sampled_from(["csv", "npy"]))
    name = f"p.{kind}"
    files[name] = draw(csv_points() if kind == "csv" else npy_points())
    out = draw(st.sampled_from(["out/e.npy", "out/e.csv"]))
    return Case(kind, files, ["irradiance", "scene.toml", "--points", name, "-o", out, "--photons", "1000",
                              "--quiet"])


# -- command lines --------------------------------------------------------------------

BAD_NUMBERS = ["0", "-1", "nan", "inf", "-inf", "1e400", "1e-400", "abc", "", " ", "2.5", "0x10", "1,2",
               "\u0661", "--", "2147483649", "99999999999999999999", "-0"]
bad_numbers = st.sampled_from(BAD_NUMBERS)


def _either(valid, bad=bad_numbers):
    return st.one_of(valid, valid, bad)


def _ints(lo, hi):
    return st.integers(lo, hi).map(str)


OPTION_KEYS = ["q", "order", "leaf_size", "k", "estimator", "extension", "count_emitted", "radius", "photons",
               "bogus", "", "max_depth", "direct", "gather", "gather_seed"]
OPTION_VALUES = ["0.6", "morton", "hilbert", "none", "8", "50", "k", "radius", "0", "0.1", "true", "false",
                 "-1", "nan", "inf", "1e400", "", "x", "1000000000", "2", "1.5", "exact", "65536"]
option = st.builds(lambda k, v, eq: f"{k}{eq}{v}", st.sampled_from(OPTION_KEYS), st.sampled_from(OPTION_VALUES),
                   st.sampled_from(["=", "=", ":", ""]))
COMMON = {
    "--method": _either(st.sampled_from(METHODS), st.sampled_from(["", "DETP", "detp ", "photonmap", "\u00fc"])),
    "--photons": _either(_ints(1, 2000)),
    "--radius": _either(st.sampled_from(["0.03", "1e-18", "1e18", "0.5", "1e-9", "3"]),
                        st.sampled_from(BAD_NUMBERS + ["1e-19", "1e19"])),
    "--seed": _either(st.one_of(_ints(0, 2**40), st.just("0")), st.sampled_from(BAD_NUMBERS + [str(2**64)])),
    "--max-depth": _either(_ints(1, 256), st.sampled_from(BAD_NUMBERS + ["257"])),
    "--device": st.sampled_from(["0:0", "0", "cpu", "9:9", "x", "", "0:", ":0", "-1:-1", "0:0:0", "\u00fc"]),
    "--local-size": st.sampled_from(["1", "2", "3", "7", "32", "64", "100", "256", "1000", "4096", "1000000",
                                     "0", "-1", "x"]),
    "-O": option,
}
IMAGE = {"--width": _either(_ints(1, 8), st.sampled_from(BAD_NUMBERS + ["16385", "100000", "1e9", "2147483648"])),
         "--height": _either(_ints(1, 8), st.sampled_from(BAD_NUMBERS + ["16385", "100000", "1e9"])),
         "--exposure": _either(st.sampled_from(["0.5", "1", "10", "1e308", "1e-300"]))}
OUT_NAMES = {
    "render": ["out/r.exr", "out/r.png", "r.EXR", "out/sub/dir/r.exr", "out/r.jpg", "out/", "", "scene.toml/r.exr",
               "out/" + "a" * 300 + ".exr", "out/\u00fcn\u00efc\u00f8d\u00e9.exr", "cornell-box", "out/r"],
    "irradiance": ["out/e.npy", "out/e.csv", "e.NPY", "out/e.txt", "", "scene.toml/e.npy", "cornell-box",
                   "out/" + "a" * 300 + ".npy"],
    "animate": ["out", "out/sub", "scene.toml", "", "p.csv/x", "out/" + "a" * 300],
    "study": ["out", "out/sub", "scene.toml", "", "p.csv/x", "out/" + "a" * 300],
}
POINT_FILES = ["p.csv", "p.npy", "missing.csv", "cornell-box", "scene.toml", "k.csv", "", "bad.npy"]
PATHS = ["line:0.1,0,0", "orbit:0.2", "orbit:0.2,2", "k.csv", "k.npy", "line:", "line:nan,0,0",
         "line:1e400,0,0", "line:1e30,0,0", "line:1e17,0,0", "orbit:-1", "orbit:0", "orbit:1e300", "spiral:1",
         "", "k.txt", "missing.csv", "line:1,2", "line:1,2,3,4", "orbit:1,nan", "orbit:0.1,1e300",
         "p.csv", "bad.npy", "m16.csv"]
STUDY = {
    "--methods": st.one_of(
        st.lists(st.sampled_from(["detp_disc_index", "impact", "photon_map", "detp_sphere_cache",
                                  "photon_map:estimator=k", "photon_map:k=8", "detp_disc_index:leaf_size=4"]),
                 min_size=1, max_size=2).map(",".join),
        st.sampled_from(["", ",", "detp,", "nope", "photon_map:k=0", "photon_map:bogus=1", "impact:q=0.5",
                         "detp:extension=nan", "photon_map:k", "detp_sphere_cache:q=2"])),
    "--photons": _either(st.lists(_ints(1, 1000), min_size=1, max_size=2).map(",".join),
                         st.sampled_from(BAD_NUMBERS + ["1,,2", ",", "100,0"])),
    "--seeds": _either(st.sampled_from(["2", "3"]), st.sampled_from(BAD_NUMBERS + ["1", "2.0"])),
    "--points": st.sampled_from(["random:4", "random:16", "vertices", "camera", "camera:4x4", "p.csv", "p.npy",
                                 "random:0", "random:-1", "random:x", "camera:0x0", "camera:4x",
                                 "camera:99999x99999", "random:1e9", "", "bad.npy", "missing.csv"]),
    "--point-seed": _either(_ints(0, 100)),
    "--reference": st.sampled_from(["detp:4000", "ref.npy", "detp", "detp:0", "detp:x", "mitsuba:0", "bad.npy",
                                    "nope.npy", "", "detp:1e400", "ref2.npy", "detp:-5"]),
    "--radius": COMMON["--radius"],
    "-O": option,
    "--spp": bad_numbers,
    "--device": COMMON["--device"],
    "--local-size": COMMON["--local-size"],
}
OPTIONS = {
    "render": {**COMMON, **IMAGE},
    "irradiance": {**COMMON, "--points": st.sampled_from(POINT_FILES)},
    "animate": {**COMMON, "--exposure": IMAGE["--exposure"],
                "--object": st.sampled_from(["cube", "cube", "", "static", "nope", "\u00fc", "mesh[0]"]),
                "--path": st.sampled_from(PATHS),
                "--frames": _either(_ints(1, 3), st.sampled_from(BAD_NUMBERS)),
                "--dynamic": st.sampled_from(["detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache",
                                              "impact", ""])},
    "study": STUDY,
}
# (--verbose is left out: the compiler output it asks for is more lines on stderr by request)
FLAGS = {"render": ["--quiet"], "irradiance": ["--quiet"], "animate": ["--quiet", "--exr"], "study": ["--quiet"]}
# Options a valid run of each command needs, and the ones that bound its work.
REQUIRED = {"irradiance": ["--points"], "animate": ["--path", "--frames"], "study": ["--seeds", "--photons",
                                                                                    "--points", "--reference"]}
STRAY = ["--bogus", "-", "--", "--photons=5", "\u00fc", "-o", "--help-me", "render", "extra.toml"]


def _cli_files() -> dict:
    files = cornell_files()
    files["scene.toml"] = CLI_SCENE.encode()
    files["cube.obj"] = CUBE_OBJ
    files["p.csv"] = b"x,y,z,nx,ny,nz\n0,0.01,0,0,1,0\n0.5,0.01,0.5,0,1,0\n0,1.98,0,0,-1,0\n0.9,1,0,-1,0,0\n"
    files["k.csv"] = b"0,0,0\n0.1,0.1,0\n0.2,0,0.1\n"
    files["m16.csv"] = b"1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1\n"

    files["p.npy"] = _npy_bytes(np.array([[0, 0.01, 0, 0, 1, 0], [0.2, 1.98, 0.1, 0, -1, 0]]))
    files["k.npy"] = _npy_bytes(np.array([[0, 0, 0, 0], [0.1, 0, 0.1, 45]]))
    files["ref.npy"] = _npy_bytes(np.ones((4, 3)))
    files["ref2.npy"] = _npy_bytes(np.full((4,), np.nan))
    files["bad.npy"] = b"\x93NUMPY\x01\x00\x10\x00{'descr': '<f8'"
    return files


@st.composite
def cli_cases(draw):
    command = draw(st.sampled_from(["render", "irradiance", "animate", "study"]))
    opts = OPTIONS[command]
    scene = draw(st.sampled_from(["scene.toml"] * 6 + ["missing.toml", "", "cornell-box", "p.csv",
                                                       "scene.toml/x", BOX_OBJ]))
    argv = [command, scene]
    chosen = set(REQUIRED.get(command, [])) | set(draw(st.lists(st.sampled_from(sorted(opts)), max_size=4)))
    for name in sorted(chosen):
        argv += [name, draw(opts[name])]
    for flag in FLAGS[command]:  # --quiet most often: a progress line is no error line
        if draw(st.integers(0, 4)) < (4 if flag == "--quiet" else 1):
            argv.append(flag)
    if command in ("irradiance", "animate", "study") or draw(st.integers(0, 2)):
        argv += ["-o", draw(st.sampled_from(OUT_NAMES[command]))]
    if draw(st.integers(0, 5)) == 0:
        argv.insert(draw(st.integers(1, len(argv))), draw(st.sampled_from(STRAY)))
    if command == "render" and "--width" not in chosen:
        argv += ["--width", "8", "--height", "8"]
    return Case("cli", _cli_files(), argv)


FORMATS = {"toml": toml_cases(), "dict": dict_cases(), "obj": line_cases("obj", BOX_OBJ, obj_lines),
           "mtl": line_cases("mtl", BOX_MTL, MTL_LINES), "ply": ply_cases(), "gltf": gltf_cases(),
           "points": points_cases(), "cli": cli_cases()}
