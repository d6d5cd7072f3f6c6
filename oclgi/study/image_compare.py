"""Comparing a rendered image with a reference image, away from edges.

Two renderers that agree on the light still disagree at geometric edges: a
pixel that straddles a silhouette or a corner is sampled at its centre by one
and averaged over its area by the other, and DETP's disc pokes out past a
corner. :func:`edge_mask` marks those pixels from the camera's query points,
and :func:`compare` gives relative-error statistics over the others, with a
colour map of the error. No renderer is needed here: plain numpy.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import params
from ..errors import OclgiError
from ..queries import QueryPoints

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 weights of linear RGB

# Two neighbouring pixels lie on one smooth surface when their normals are
# within ~25 degrees and each lies near the other's tangent plane: on one
# plane the offset along the normal is rounding, across a step it is of the
# order of the pixels' spacing.
NORMAL_COS = 0.9
PLANE_TOLERANCE = 0.1
MASKED_GREY = (128, 128, 128, 255)


def _neighbour_pairs(h, w):
    """(a, b) index arrays of horizontally and vertically adjacent pixels."""
    idx = np.arange(h * w).reshape(h, w)
    return (np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()]),
            np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()]))


def discontinuities(points: QueryPoints, scene=None) -> np.ndarray:
    """(H, W) bool: pixels on either side of a geometric discontinuity.

    Between two 4-neighbours: one sees the background and the other does not,
    their normals differ by more than ~25 degrees, or one lies off the
    other's tangent plane (a step in depth). With ``scene``, a change of
    material (an emitter flush with a ceiling) or of object counts too.
    Background pixels themselves are marked.
    """
    if not isinstance(points, QueryPoints) or points.shape is None:
        raise OclgiError("edge_mask needs camera points (engine.camera_points()), with their image shape")
    h, w = points.shape
    if len(points) != h * w:
        raise OclgiError(f"camera points: {len(points)} points for a {w}x{h} image")
    tri = points.tri
    hit = tri >= 0
    p = points.xyz.astype(np.float64)
    n = points.normals[:, :3].astype(np.float64)
    a, b = _neighbour_pairs(h, w)
    both = hit[a] & hit[b]
    cut = hit[a] != hit[b]
    dp = p[b] - p[a]
    gap = np.linalg.norm(dp, axis=1)
    off_a = np.abs(np.einsum("ij,ij->i", dp, n[a]))
    off_b = np.abs(np.einsum("ij,ij->i", dp, n[b]))
    bent = np.einsum("ij,ij->i", n[a], n[b]) < NORMAL_COS
    step = np.maximum(off_a, off_b) > PLANE_TOLERANCE * gap
    cut |= both & (bent | step)
    if scene is not None:
        if hit.any() and tri.max() >= len(scene.tri_material):
            raise OclgiError("the camera points do not belong to this scene (triangle index out of range)")
        t = np.where(hit, tri, 0)
        mat, obj = scene.tri_material[t], scene.tri_object[t]
        cut |= both & ((mat[a] != mat[b]) | (obj[a] != obj[b]))
    edge = ~hit.copy()
    edge[a[cut]] = True
    edge[b[cut]] = True
    return edge.reshape(h, w)


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Square dilation of a 2-D bool mask by ``radius`` pixels."""
    out = mask.copy()
    h, w = mask.shape
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dy == 0 and dx == 0:
                continue
            src = mask[max(0, -dy):h - max(0, dy), max(0, -dx):w - max(0, dx)]
            out[max(0, dy):h - max(0, -dy), max(0, dx):w - max(0, -dx)] |= src
    return out


def edge_mask(points: QueryPoints, edge_px: int = 3, scene=None, spp: int = 1) -> np.ndarray:
    """(H, W) bool, True = leave out: the background, and every pixel within
    ``edge_px`` pixels (a square of side 2 edge_px + 1) of a pixel touching a
    geometric discontinuity (see :func:`discontinuities`). ``edge_px = 0``
    masks only the pixels that touch one. ``spp`` > 1: the points are a
    render's stacked samples (``Engine.camera_points``), and a pixel is left
    out when any of its samples is (mirrors and glass: each sample's own
    path)."""
    if isinstance(edge_px, bool) or not isinstance(edge_px, (int, np.integer)) or edge_px < 0:
        raise OclgiError(f"edge_px must be an integer >= 0, got {edge_px!r}")
    spp = params.samples_per_pixel(spp)
    if spp == 1 or getattr(points, "shape", None) is None:  # (discontinuities checks the points)
        return dilate(discontinuities(points, scene), int(edge_px))
    h, w = points.shape
    if h % spp:
        raise OclgiError(f"edge_mask: {h} rows of points are not {spp} samples of an image")
    masks = [dilate(discontinuities(points.subset(slice(k * (h // spp) * w, (k + 1) * (h // spp) * w))
                                    .reshaped((h // spp, w)), scene), int(edge_px)) for k in range(spp)]
    return np.logical_or.reduce(masks)


@dataclass
class Comparison:
    """Relative error of a test image against a reference, over the unmasked
    pixels (``compared`` of them) whose reference luminance is positive."""

    compared: int  # pixels in the statistics
    masked: int  # pixels left out by the mask
    dark: int  # unmasked pixels with zero reference luminance, left out too
    rel_mean: float  # mean |t - r| / r of luminance
    rel_median: float
    rel_p95: float
    signed_mean: float  # mean (t - r) / r of luminance: the bias
    channel_ratio: tuple  # per channel, mean(t) / mean(r) over the compared pixels
    error: np.ndarray = field(repr=False)  # (H, W) float32 signed (t - r) / r of luminance; 0 where left out
    error_rgba: np.ndarray = field(repr=False)  # (H, W, 4) uint8: the colour ramp, left-out pixels grey
    scale: float = 0.2  # the colour ramp's full scale (relative error)

    def summary(self) -> dict:
        """The statistics as plain numbers (JSON-ready)."""
        return {"compared_pixels": self.compared, "masked_pixels": self.masked, "dark_pixels": self.dark,
                "rel_error_mean": self.rel_mean, "rel_error_median": self.rel_median,
                "rel_error_p95": self.rel_p95, "signed_rel_error_mean": self.signed_mean,
                "channel_mean_ratio": list(self.channel_ratio), "colour_scale": self.scale}


def _image(a, name):
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise OclgiError(f"{name} image must be an (H, W, 3) array, got shape {a.shape}")
    if a.dtype.kind not in "iuf":
        raise OclgiError(f"{name} image must hold numbers, got {a.dtype}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        raise OclgiError(f"{name} image has {int((~np.isfinite(a)).any(axis=2).sum())} NaN or infinite pixels")
    return a


def compare(test, reference, mask=None, scale: float = 0.2) -> Comparison:
    """Statistics of the relative error of ``test`` against ``reference``.

    Both are (H, W, 3) linear images; ``mask`` (H, W) bool marks the pixels
    to leave out (:func:`edge_mask`), None leaves out none. The error is
    taken on luminance; ``channel_ratio`` checks colour balance. ``scale`` is
    the relative error shown at full colour in ``error_rgba`` (blue: test
    lower, red: test higher).
    """
    t, r = _image(test, "test"), _image(reference, "reference")
    if t.shape != r.shape:
        raise OclgiError(f"test and reference images differ in shape: {t.shape} and {r.shape}")
    h, w = t.shape[:2]
    mask = np.zeros((h, w), bool) if mask is None else np.asarray(mask)
    if mask.shape != (h, w) or mask.dtype != bool:
        raise OclgiError(f"mask must be an (H, W) = ({h}, {w}) bool array, got {mask.dtype} {mask.shape}")
    if not (np.isfinite(scale) and scale > 0):
        raise OclgiError(f"colour scale must be a positive number, got {scale!r}")
    lt, lr = t @ LUMINANCE, r @ LUMINANCE
    dark = ~mask & ~(lr > 0)
    use = ~mask & ~dark
    if not use.any():
        raise OclgiError("no pixel left to compare (all masked or black in the reference)")
    signed = np.zeros((h, w))
    signed[use] = (lt[use] - lr[use]) / lr[use]
    rel = np.abs(signed[use])
    ratio = t[use].mean(axis=0) / np.maximum(r[use].mean(axis=0), 1e-300)
    return Comparison(
        compared=int(use.sum()), masked=int(mask.sum()), dark=int(dark.sum()),
        rel_mean=float(rel.mean()), rel_median=float(np.median(rel)), rel_p95=float(np.percentile(rel, 95)),
        signed_mean=float(signed[use].mean()), channel_ratio=tuple(float(x) for x in ratio),
        error=signed.astype(np.float32), error_rgba=error_colours(signed, ~use, scale), scale=float(scale))


def error_colours(signed: np.ndarray, left_out: np.ndarray, scale: float) -> np.ndarray:
    """(H, W, 4) uint8: a diverging ramp, white at 0, blue at -scale, red at
    +scale (clamped); left-out pixels grey."""
    x = np.clip(signed / scale, -1.0, 1.0)
    pos, neg = np.clip(x, 0, 1), np.clip(-x, 0, 1)
    rgb = np.stack([1.0 - 0.8 * neg, 1.0 - 0.8 * (pos + neg), 1.0 - 0.8 * pos], axis=-1)
    out = np.empty(signed.shape + (4,), np.uint8)
    out[..., :3] = np.round(255 * rgb)
    out[..., 3] = 255
    out[left_out] = MASKED_GREY
    return out
