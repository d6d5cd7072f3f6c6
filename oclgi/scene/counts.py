"""PLY and OFF headers checked against their data before trimesh reads them.

Both formats declare their element counts up front, and trimesh trusts
them: a PLY or OFF that declares 4 vertices and gives 3 loads with the
first face's numbers as the fourth vertex and no face, without a word, and
an ASCII PLY declaring 10^10 faces loads whatever follows. Here the declared
counts must fit in the file's size (checked before anything is allocated
for them) and match the data exactly: in ASCII files one line per element
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
        return 2 * len(e.props) if fmt == "ascii" else sum(np.dtype(a).itemsize for a, _ in e.props)
    need = sum(e.count * least(e) for e in elements)
    if need > body:
        counts = _counts(elements)
        _fail(path, "PLY", f"its header declares {counts}, more than its {body:,} bytes of data can hold")
    if fmt == "ascii":
        _check_ply_ascii(path, data[start:], elements)
    else:
        _check_ply_binary(path, data[start:], elements, _PLY_FORMATS[fmt])


_SPACE = np.zeros(256, bool)
_SPACE[list(b" \t\r\n\v\f")] = True


class _Words:
    """The words of an ASCII body, found with numpy (a list of words per line
    would cost more than trimesh's whole read): for each non-blank line, its
    number of words and where its first word is."""

    def __init__(self, body: bytes):
        self.body = body
        self.bytes = a = np.frombuffer(body, np.uint8)
        space = _SPACE[a]
        word = ~space
        self.starts = np.flatnonzero(word & np.concatenate(([True], space[:-1])))
        self.ends = np.flatnonzero(word & np.concatenate((space[1:], [True]))) + 1
        line = np.searchsorted(np.flatnonzero(a == 10), self.starts)  # each word's line, ascending
        self.first = np.flatnonzero(np.diff(line, prepend=-1))  # each line's first word
        self.count = np.diff(self.first, append=len(line))

    def __len__(self) -> int:
        return len(self.first)

    def numbers(self, rows: slice, k: int) -> np.ndarray:
        """Word ``k`` of each of ``rows`` as a whole number; -1 where it is none."""
        first, count = self.first[rows], self.count[rows]
        out = np.full(len(first), -1, np.int64)
        has = np.flatnonzero(count > k)
        start = self.starts[first[has] + k]
        size = self.ends[first[has] + k] - start
        # up to 9 digits, read as a table of digits: far more than any list holds
        cols = np.arange(9)
        inside = cols < size[:, None]
        digits = self.bytes[start[:, None] + np.minimum(cols, size[:, None] - 1)].astype(np.int64) - 48
        ok = (size <= 9) & (((digits >= 0) & (digits <= 9)) | ~inside).all(axis=1)
        scale = np.where(inside, 10 ** np.maximum(size[:, None] - 1 - cols, 0), 0)
        out[has[ok]] = (digits * scale).sum(axis=1)[ok]
        return out

    def row(self, r: int) -> list:
        w = slice(self.first[r], self.first[r] + self.count[r])
        return [self.body[s:e].decode("latin-1") for s, e in zip(self.starts[w], self.ends[w])]


def _first_bad(ok: np.ndarray) -> int:
    """The first index where ``ok`` is False; -1 if none."""
    return int(np.argmin(ok)) if len(ok) and not ok.all() else -1


def _check_ply_ascii(path, body, elements):
    words = _Words(body)
    declared = sum(e.count for e in elements)
    if len(words) != declared:
        _fail(path, "PLY", f"its header declares {_counts(elements)} ({declared:,} lines of data), "
                           f"the file holds {len(words):,} lines")
    first = 0
    for e in elements:
        rows = slice(first, first + e.count)
        lists = [k for k, (_, item) in enumerate(e.props) if item is not None]
        if len(lists) <= 1:
            # the usual layouts (scalars, at most one list), for all rows at once
            want = np.full(e.count, len(e.props), np.int64)
            ok = np.ones(e.count, bool)
            if lists:
                n = words.numbers(rows, lists[0])
                ok, want = n >= 0, want + n
            bad = _first_bad(ok & (words.count[rows] == want))
        else:
            bad = next((i for i in range(e.count)
                        if _words_wanted(row := words.row(first + i), e.props) != len(row)), -1)
        if bad >= 0:
            _fail(path, "PLY", f"{e.name} {bad} (data line {first + bad + 1}) does not hold the numbers "
                               "its header's properties call for")
        first += e.count


def _words_wanted(words, props) -> int:
    """How many words a row of ``props`` holds, by its list lengths; -1 if it cannot."""
    at = 0
    for _, item in props:
        if item is not None:
            if at >= len(words) or not (words[at].isascii() and words[at].isdigit()):
                return -1
            at += int(words[at])
        at += 1
    return at


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
    if b"#" in data:
        data = b"\n".join(line.split(b"#", 1)[0] for line in data.splitlines())
    words = _Words(data)
    head = words.row(0) if len(words) else []
    if not head or not re.fullmatch(r"C?N?OFF", head[0]):
        _fail(path, "OFF", "it does not start with 'OFF'")
    counts, first = (head[1:], 1) if head[1:] else (words.row(1) if len(words) > 1 else [], 2)
    if len(counts) not in (2, 3) or not all(w.isascii() and w.isdigit() for w in counts):
        _fail(path, "OFF", "the line after 'OFF' must give the vertex, face (and edge) counts")
    nv, nf = int(counts[0]), int(counts[1])
    if nv + nf != len(words) - first:
        _fail(path, "OFF", f"its header declares {nv:,} vertices and {nf:,} faces, "
                           f"{nv + nf:,} lines of data; the file holds {len(words) - first:,} lines")
    bad = _first_bad(words.count[first:first + nv] >= 3)
    if bad >= 0:
        _fail(path, "OFF", f"vertex {bad} has fewer than 3 coordinates")
    faces = slice(first + nv, first + nv + nf)
    n = words.numbers(faces, 0)
    # a face line may go on past its indices (a colour)
    bad = _first_bad((n >= 3) & (words.count[faces] >= 1 + n))
    if bad >= 0:
        _fail(path, "OFF", f"face {bad} does not give its count and that many vertex indices")
