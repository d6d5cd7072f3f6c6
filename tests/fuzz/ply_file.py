"""Writing PLY files, ASCII or binary, whose header may lie.

The header's counts, the body's rows and the property types are given
separately, so a case can declare 8 vertices and write 5, or list a face
with 2 indices, exactly as a broken exporter would.
"""

from __future__ import annotations

import math
import struct

# PLY type name -> struct code
TYPES = {"char": "b", "uchar": "B", "short": "h", "ushort": "H", "int": "i", "uint": "I",
         "float": "f", "double": "d", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H",
         "int32": "i", "uint32": "I", "float32": "f", "float64": "d"}


def _whole(x) -> bool:
    return math.isfinite(x) and abs(x) < 1e30


def _pack(code: str, x, order: str) -> bytes:
    try:
        return struct.pack(order + code, x)
    except (struct.error, OverflowError, TypeError):
        # a value the type cannot hold: its bytes wrapped, as a C writer would cast it
        if code in "fd":
            return struct.pack(order + code, float("nan"))
        size = struct.calcsize(code)
        return (int(x) % (1 << (8 * size))).to_bytes(size, "little" if order == "<" else "big")


def write(fmt: str, vertex_type: str, index_types: tuple, vertices, faces, vertex_count=None,
          face_count=None, extra_header=(), truncate=None) -> bytes:
    """A PLY file: ``fmt`` is ascii, binary_little_endian or binary_big_endian;
    ``vertices`` rows of x y z, ``faces`` lists of indices (any length)."""
    count_type, index_type = index_types
    head = ["ply", f"format {fmt} 1.0",
            f"element vertex {len(vertices) if vertex_count is None else vertex_count}",
            f"property {vertex_type} x", f"property {vertex_type} y", f"property {vertex_type} z",
            f"element face {len(faces) if face_count is None else face_count}",
            f"property list {count_type} {index_type} vertex_indices", *extra_header, "end_header"]
    header = ("\n".join(head) + "\n").encode("utf-8", "surrogatepass")
    if fmt == "ascii":
        floats = TYPES.get(vertex_type, "f") in "fd"
        body = "".join(" ".join(repr(float(x)) if floats or not _whole(x) else str(int(x))
                                for x in v) + "\n" for v in vertices)
        body += "".join(" ".join(str(x) for x in [len(f), *f]) + "\n" for f in faces)
        data = header + body.encode()
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        out = bytearray(header)
        vc = TYPES.get(vertex_type, "f")
        for v in vertices:
            for x in v:
                out += _pack(vc, x if vc in "fd" else int(x) if _whole(x) else 0, order)
        cc, ic = TYPES.get(count_type, "B"), TYPES.get(index_type, "i")
        for f in faces:
            out += _pack(cc, len(f), order)
            for x in f:
                out += _pack(ic, x, order)
        data = bytes(out)
    if truncate is not None:
        data = data[:max(0, int(len(data) * truncate))]
    return data
