"""PLY and OFF headers checked against their data before trimesh reads them.

Both formats declare their element counts up front, and trimesh trusts
them: a PLY or OFF that declares 4 vertices and gives 3 loads with the
first face's numbers as the fourth vertex and no face, without a word; a
header declaring 10^10 faces would have memory set aside for them. Here the
declared counts must fit in the file's size (checked before anything is
allocated) and match the data exactly: in ASCII files one line per element
with the numbers its properties call for, in binary PLY the exact number of
bytes.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import OclgiError

_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4", "uint": "u4",
              "float": "f4", "double": "f8", "int8": "i1", "uint8": "u1", "int16": "i2", "uint16": "u2",
              "int32": "i4", "uint32": "u4", "float32": "f4", "float64": "f8"}
_PLY_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
# Enough of a file to hold any real header; past this it is not a PLY header.
_MAX_HEADER = 1 << 20


@dataclass
class _Element:
    name: str
    count: int
    props: list = field(default_factory=list)  # (dtype, None) scalars, (count dtype, item dtype) lists


def check_counts(path: Path, data: bytes, suffix: str) -> None:
    """Refuse a PLY or OFF ``data`` whose declared counts disagree with it."""
    if suffix == ".ply":
        _check_ply(path, data)
    elif suffix == ".off":
        _check_off(path, data)


def _fail(path, kind, problem):
    raise OclgiError(f"{path}: cannot read {kind} file: {problem}")


# -- PLY ---------------------------------------------------------------------------------

def _ply_header(path, data):
    if not data.startswith(b"ply"):
        _fail(path, "PLY", "it does not start with 'ply'")
    m = re.search(rb"end_header[ \t]*\r?\n", data[:_MAX_HEADER])
    if m is None:
        _fail(path, "PLY", "no 'end_header' line ends its header")
    try:
        lines = data[:m.start()].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        _fail(path, "PLY", "its header is not plain text")
    fmt, elements = None, []
    for lineno, line in enumerate(lines, 2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3 and words[1] in _PLY_FORMATS:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            if not re.fullmatch(r"[0-9]+", words[2]):
                _fail(path, "PLY", f"header line {lineno}: element {words[1]!r} has no count ({words[2]!r})")
            elements.append(_Element(words[1], int(words[2])))
        elif words[0] == "property" and elements:
            is_list = words[1:2] == ["list"]
            types = words[2:-1] if is_list else words[1:-1]
            if any(t not in _PLY_TYPES for t in types) or len(types) != (2 if is_list else 1):
                _fail(path, "PLY", f"header line {lineno}: unknown property type in {line.strip()!r}")
            elements[-1].props.append((_PLY_TYPES[types[0]], _PLY_TYPES[types[1]] if len(types) == 2 else None))
        else:
            _fail(path, "PLY", f"header line {lineno}: not a PLY header line: {line.strip()!r}")
    if fmt is None:
        _fail(path, "PLY", "its header names no format (ascii, binary_little_endian or binary_big_endian)")
    return fmt, elements, m.end()


def _counts(elements) -> str:
    return "element counts " + ", ".join(f"{e.name} {e.count:,}" for e in elements)


def _check_ply(path, data):
    fmt, elements, start = _ply_header(path, data)
    body = len(data) - start
    # the least each row takes: a byte per scalar and its separator in ASCII,
    # the scalars and list lengths in binary
    def least(e):
        if fmt == "ascii":
            return 2 * len(e.props)
        return sum(np.dtype(a).itemsize for a, _ in e.props)
    need = sum(e.count * least(e) for e in elements)
    if need > body:
        counts = _counts(elements)
        _fail(path, "PLY", f"its header declares {counts}, more than its {body:,} bytes of data can hold")
    if fmt == "ascii":
        _check_ply_ascii(path, data[start:], elements)
    else:
        _check_ply_binary(path, data[start:], elements, _PLY_FORMATS[fmt])


def _check_ply_ascii(path, body, elements):
    lines = [line for line in body.decode("latin-1").splitlines() if line.strip()]
    declared = sum(e.count for e in elements)
    if len(lines) != declared:
        counts = _counts(elements)
        _fail(path, "PLY", f"its header declares {counts} ({declared:,} lines of data), "
                           f"the file holds {len(lines):,} lines")
    row = 0
    for e in elements:
        for i in range(e.count):
            words = lines[row].split()
            at = 0
            for _, item in e.props:
                if item is not None:
                    if at >= len(words) or not re.fullmatch(r"[0-9]+", words[at]):
                        at = -1
                        break
                    at += int(words[at])
                at += 1
            if at != len(words):
                _fail(path, "PLY", f"{e.name} {i} (data line {row + 1}) does not hold the numbers "
                                   "its header's properties call for")
            row += 1


def _check_ply_binary(path, body, elements, order):
    at = 0
    for e in elements:
        lists = [k for k, (_, item) in enumerate(e.props) if item is not None]
        sizes = [np.dtype(a).itemsize for a, _ in e.props]
        if not lists:
            at += e.count * sum(sizes)
            continue
        if e.count and len(lists) == 1:
            # the usual case: one list, as long in every row as in the first
            k = lists[0]
            ctype = np.dtype(order + e.props[k][0])
            isize = np.dtype(order + e.props[k][1]).itemsize
            pos = at + sum(sizes[:k])
            if pos + ctype.itemsize <= len(body):
                n = int(np.frombuffer(body, ctype, 1, pos)[0])
                row = sum(sizes) + n * isize
                if at + e.count * row <= len(body):
                    lens = np.ndarray((e.count,), ctype, body, pos, (row,))
                    if (lens == n).all():
                        _face_size(path, e, 0, n)
                        at += e.count * row
                        continue
        at = _walk_rows(path, body, at, e, order)
    if at != len(body):
        counts = _counts(elements)
        _fail(path, "PLY", f"its header declares {counts}, which take {at:,} bytes; "
                           f"the file holds {len(body):,} bytes")


def _face_size(path, e, i, n):
    """A face lists 3 vertices or more (fewer: the counts have shifted)."""
    if e.name == "face" and n < 3:
        _fail(path, "PLY", f"face {i} lists {n} vertices; a face needs at least 3")


def _walk_rows(path, body, at, e, order):
    """Row by row, for lists whose lengths vary: where element ``e`` ends."""
    for i in range(e.count):
        for a, item in e.props:
            size = np.dtype(a).itemsize
            if at + size > len(body):
                _fail(path, "PLY", f"the data ends inside {e.name} {i}")
            if item is None:
                at += size
                continue
            n = int(np.frombuffer(body, np.dtype(order + a), 1, at)[0])
            if n < 0:
                _fail(path, "PLY", f"{e.name} {i} has a list of negative length {n}")
            _face_size(path, e, i, n)
            at += size + n * np.dtype(item).itemsize
    return at


# -- OFF ---------------------------------------------------------------------------------

def _check_off(path, data):
    text = data.decode("latin-1")
    lines = [line.split("#", 1)[0].split() for line in text.splitlines()]
    lines = [words for words in lines if words]
    if not lines or not re.fullmatch(r"C?N?OFF", lines[0][0]):
        _fail(path, "OFF", "it does not start with 'OFF'")
    rest = lines[0][1:] or (lines[1] if len(lines) > 1 else [])
    first = 1 if lines[0][1:] else 2
    if len(rest) not in (2, 3) or not all(re.fullmatch(r"[0-9]+", w) for w in rest):
        _fail(path, "OFF", "the line after 'OFF' must give the vertex, face (and edge) counts")
    nv, nf = int(rest[0]), int(rest[1])
    body = lines[first:]
    if nv + nf != len(body):
        _fail(path, "OFF", f"its header declares {nv:,} vertices and {nf:,} faces, "
                           f"{nv + nf:,} lines of data; the file holds {len(body):,} lines")
    for i, words in enumerate(body[:nv]):
        if len(words) < 3:
            _fail(path, "OFF", f"vertex {i} has fewer than 3 coordinates")
    for i, words in enumerate(body[nv:]):
        if not re.fullmatch(r"[0-9]+", words[0]) or int(words[0]) < 3 or len(words) < 1 + int(words[0]):
            _fail(path, "OFF", f"face {i} does not give its count and that many vertex indices")
