"""Albedo textures: images read with OpenImageIO, decoded to linear RGB, and
packed for the device (``kernels/texture.h`` samples them).

An image's pixels are the reflectance it multiplies the material's albedo
by. Integer images (8 or 16 bits: PNG, JPEG, TGA, ...) are sRGB-encoded and
decoded to linear here, before any filtering (filtering encoded values
would darken edges); float images (EXR, HDR) are linear as they are, and
must lie in [0, 1]. Alpha is dropped; a grey image is used for all three
channels.

On the device all of a scene's textures are one array of float4 texels,
each texture a record (offset, width, height) in it
(``oclgi.cl.layout.Texture``); lookups are bilinear and repeat outside
[0, 1) (OBJ's and glTF's default), with v pointing up the image (row 0 is
the top row, at v = 1).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..cl.layout import Texture
from ..errors import OclgiError

MAX_SIDE = 16384  # texels per side
MAX_TEXELS = 2**28  # of all of a scene's textures together (4 GiB of float4)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def from_array(pixels, what: str, encoded: bool) -> np.ndarray:
    """(H, W, 3) float32 linear reflectance from an (H, W), (H, W, C) image;
    ``encoded``: its values are sRGB (integers scaled to [0, 1])."""
    a = np.asarray(pixels)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] == 0 or not (1 <= a.shape[0] <= MAX_SIDE and 1 <= a.shape[1] <= MAX_SIDE):
        raise OclgiError(f"{what}: expected an image of 1 to {MAX_SIDE} pixels per side, got shape {a.shape}")
    if a.dtype.kind in "ui":
        a = a.astype(np.float64) / np.iinfo(a.dtype).max
    elif a.dtype.kind == "f":
        a = a.astype(np.float64)
    else:
        raise OclgiError(f"{what}: pixels must be numbers, got {a.dtype}")
    rgb = a[:, :, :3] if a.shape[2] >= 3 else np.repeat(a[:, :, :1], 3, axis=2)
    if not np.isfinite(rgb).all() or rgb.min() < 0 or rgb.max() > 1:
        raise OclgiError(f"{what}: an albedo texture's values must lie in [0, 1] (got {np.nanmin(rgb):.3g} .. "
                         f"{np.nanmax(rgb):.3g})")
    if encoded:
        rgb = srgb_to_linear(rgb)
    return np.ascontiguousarray(rgb, np.float32)


def read(path: Path) -> np.ndarray:
    """An image file as (H, W, 3) float32 linear reflectance (module doc)."""
    import OpenImageIO as oiio

    path = Path(path)
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OclgiError(f"cannot read texture {path}: {oiio.geterror() or 'not an image OpenImageIO reads'}")
    try:
        spec = inp.spec()
        if spec.width > MAX_SIDE or spec.height > MAX_SIDE or spec.width < 1 or spec.height < 1:
            raise OclgiError(f"texture {path}: {spec.width} x {spec.height} pixels; at most {MAX_SIDE} per side")
        integer = spec.format.basetype in (oiio.UINT8, oiio.UINT16, oiio.INT8, oiio.INT16)
        space = str(spec.get_string_attribute("oiio:ColorSpace", "")).lower()
        pixels = inp.read_image(format=oiio.FLOAT)
    finally:
        inp.close()
    if pixels is None:
        raise OclgiError(f"cannot read texture {path}: {oiio.geterror()}")
    encoded = (integer or "srgb" in space) and "linear" not in space
    return from_array(np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels), f"texture {path}",
                      encoded)


def read_bytes(data: bytes, name: str) -> np.ndarray:
    """An image file's bytes (a zip member) read as :func:`read` reads a file."""
    import tempfile

    suffix = Path(name).suffix or ".png"
    with tempfile.TemporaryDirectory(prefix="oclgi-texture-") as d:
        f = Path(d) / ("texture" + suffix)
        f.write_bytes(data)
        try:
            return read(f)
        except OclgiError as exc:
            raise OclgiError(str(exc).replace(str(f), name)) from None


def from_image(image, what: str) -> np.ndarray:
    """An image trimesh decoded from a glTF file (PIL), as :func:`read` returns."""
    return from_array(np.asarray(image.convert("RGB")), what, encoded=True)


def pack(textures: list) -> tuple[np.ndarray, np.ndarray]:
    """(records, texels): the ``Texture`` records and one float4 texel array."""
    total = sum(t.shape[0] * t.shape[1] for t in textures)
    if total > MAX_TEXELS:
        raise OclgiError(f"the scene's textures hold {total:,} texels; at most {MAX_TEXELS:,} are supported")
    records = np.zeros(max(len(textures), 1), Texture)
    texels = np.zeros((max(total, 1), 4), np.float32)
    offset = 0
    for i, t in enumerate(textures):
        h, w = t.shape[:2]
        records[i] = (offset, w, h, 0)
        texels[offset:offset + h * w, :3] = t.reshape(-1, 3)
        offset += h * w
    return records, texels


def affine_maps(tri_vertices: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(F, k, 4) float64: per triangle and per component of ``values`` (F,
    3, k), given at its corners, the affine map (m, c) from a point p of
    its plane (object space) to the value there, m . p + c. A point's
    barycentrics are linear in it, so the map is exact on the triangle: the
    device needs no barycentrics to texture or colour a photon's hit
    (kernels/texture.h). NaN values (a corner without one) count as 0."""
    v0 = tri_vertices[:, 0]
    e1, e2 = tri_vertices[:, 1] - v0, tri_vertices[:, 2] - v0
    # the dual basis of (e1, e2) in the plane: g1 . e1 = 1, g1 . e2 = 0, ...
    a, b, c = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    det = a * c - b * b
    det = np.where(det > 0, det, 1.0)
    g1 = (c[:, None] * e1 - b[:, None] * e2) / det[:, None]
    g2 = (a[:, None] * e2 - b[:, None] * e1) / det[:, None]
    val = np.nan_to_num(values, nan=0.0)
    d1, d2 = val[:, 1] - val[:, 0], val[:, 2] - val[:, 0]
    out = np.zeros((len(v0), val.shape[2], 4), np.float64)
    for k in range(val.shape[2]):  # value_k(p) = value0_k + (p - v0) . (d1_k g1 + d2_k g2)
        m = d1[:, k:k + 1] * g1 + d2[:, k:k + 1] * g2
        out[:, k, :3] = m
        out[:, k, 3] = val[:, 0, k] - (m * v0).sum(1)
    return out


def uv_maps(tri_vertices: np.ndarray, tri_uv: np.ndarray) -> np.ndarray:
    """(F, 8) float32: the affine maps (:func:`affine_maps`) to texture
    coordinates, rows (m_u, c_u, m_v, c_v)."""
    return affine_maps(tri_vertices, tri_uv).reshape(len(tri_uv), 8).astype(np.float32)


def colour_maps(tri_vertices: np.ndarray, tri_colour: np.ndarray) -> np.ndarray:
    """(3 F, 4) float32: the affine maps to the vertex colours' R, G and B,
    three float4 rows per triangle; corners without a colour are white."""
    colour = np.where(np.isnan(tri_colour), 1.0, tri_colour)
    return affine_maps(tri_vertices, colour).reshape(3 * len(tri_colour), 4).astype(np.float32)
