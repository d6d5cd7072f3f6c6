"""Writing glTF 2.0 files (.gltf with an embedded buffer, or .glb) from a
JSON document that a case may then break: a mesh of one primitive, its
positions (float VEC3) and indices, a node, a scene and a material."""

from __future__ import annotations

import base64
import json
import struct

import numpy as np

INDEX_TYPES = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}


def document(vertices, faces, index_type=5125, base_color=(0.8, 0.8, 0.8, 1.0),
             emissive=(0.0, 0.0, 0.0), matrix=None) -> tuple[dict, bytes]:
    """The glTF JSON and its binary buffer (positions, then indices)."""
    with np.errstate(all="ignore"):  # a huge coordinate becomes float32's inf, as an exporter writes it
        pos = np.asarray(vertices, np.float32).reshape(-1, 3)
    idx = np.asarray([min(max(int(i), -2**63), 2**63 - 1) for i in faces], np.int64)  # int64 as a writer casts
    dtype = INDEX_TYPES.get(index_type, np.uint32)
    idx_bytes = (idx % (np.iinfo(dtype).max + 1)).astype(dtype).tobytes()
    pos_bytes = pos.tobytes()
    pad = (-len(pos_bytes)) % 4
    blob = pos_bytes + b"\0" * pad + idx_bytes
    blob += b"\0" * ((-len(blob)) % 4)
    finite = pos[np.isfinite(pos).all(axis=1)] if len(pos) else pos
    lo = finite.min(axis=0).tolist() if len(finite) else [0, 0, 0]
    hi = finite.max(axis=0).tolist() if len(finite) else [0, 0, 0]
    node = {"mesh": 0}
    if matrix is not None:
        node["matrix"] = list(matrix)
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [node],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0, "mode": 4}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": list(base_color)},
                       "emissiveFactor": list(emissive)}],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos_bytes)},
                        {"buffer": 0, "byteOffset": len(pos_bytes) + pad, "byteLength": len(idx_bytes)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
                       "min": lo, "max": hi},
                      {"bufferView": 1, "componentType": index_type, "count": len(idx), "type": "SCALAR"}],
    }
    return doc, blob


def _json(doc) -> bytes:
    # allow_nan: a NaN factor is written as NaN, which some readers take
    return json.dumps(doc, allow_nan=True).encode("utf-8", "surrogatepass")


def gltf(doc: dict, blob: bytes) -> bytes:
    """A .gltf file: the buffer embedded as a data URI."""
    doc = json.loads(json.dumps(doc))  # a copy, NaN kept
    if doc.get("buffers") and isinstance(doc["buffers"], list) and isinstance(doc["buffers"][0], dict):
        doc["buffers"][0].setdefault(
            "uri", "data:application/octet-stream;base64," + base64.b64encode(blob).decode())
    return _json(doc)


def glb(doc: dict, blob: bytes, length_delta: int = 0, json_chunk_delta: int = 0) -> bytes:
    """A .glb file; the deltas make its header's total length or its JSON
    chunk's length lie."""
    text = _json(doc)
    text += b" " * ((-len(text)) % 4)
    chunks = struct.pack("<I4s", (len(text) + json_chunk_delta) % (1 << 32), b"JSON") + text
    chunks += struct.pack("<I4s", len(blob), b"BIN\0") + blob
    return struct.pack("<4sII", b"glTF", 2, (12 + len(chunks) + length_delta) % (1 << 32)) + chunks
