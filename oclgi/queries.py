"""Query points: where irradiance is estimated.

Three sources: the visible point of each pixel of a camera (computed on the
device by ``kernels/camera.cl``), the mesh vertices (normals averaged over
the adjacent triangles, weighted by area), and arbitrary points with normals
given by the user (sensors, reference positions). Each point carries a unit
normal: DETP counts light arriving on the normal's side.

Layout (float32): positions (n, 4) with w = the triangle under the point as
int bits (-1 when unknown or none), normals (n, 4), barycentrics (n, 2) on
that triangle. Impact Count needs the triangle; DETP does not.

The device reads these arrays as they are, so a QueryPoints is checked when
it is made (:meth:`QueryPoints.__post_init__`): float32 arrays of these
shapes are taken as they are (w as int bits); other real arrays, or (n, 3)
positions and normals, are converted (w then read as a number: the triangle
id); bool, complex, string and object arrays are refused, as are NaN,
infinite or huge coordinates and normals that are neither of unit length
nor zero (a point that counts nothing, as a camera's pixel that sees nothing). The
triangle ids are checked against a scene where the points meet an engine
(:meth:`QueryPoints.check_triangles`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import OclgiError
from .params import MAX_LENGTH

# Coordinates the device squares in float32 (as the scene's vertices: params.MAX_LENGTH).
MAX_COORDINATE = MAX_LENGTH
# How far from 1 a normal's length may be: the kernels take normals as unit
# vectors (DETP's disc plane, the side a point faces); float32 rounding of a
# normalised vector is far inside this.
NORMAL_TOLERANCE = 1e-3


def _array(value, name: str, columns: tuple, n: int | None) -> np.ndarray:
    """``value`` as a C-contiguous float32 (n, columns[-1]) array, or an error
    naming ``name``. Float32 input of the full width is taken as it is (its
    last column may hold int bits); real input of another dtype is converted
    by value; a narrower width is padded by the caller."""
    a = np.asarray(value) if not isinstance(value, np.ndarray) else value
    if a.dtype.kind not in "iuf":
        raise OclgiError(f"query points: {name} must be an array of real numbers, got dtype {a.dtype}")
    if a.ndim != 2 or a.shape[1] not in columns or (n is not None and len(a) != n):
        want = " or ".join(f"(n, {c})" for c in columns)
        rows = f" of {n} rows" if n is not None else ""
        raise OclgiError(f"query points: {name} must be a {want} array{rows}, got shape {a.shape}")
    return a


def _finite_rows(a: np.ndarray, name: str, limit: float | None = None) -> None:
    # one reduction over the whole array first: a per-row one (axis=1 on a
    # few columns) costs ten times as much, and is only needed to name a row
    with np.errstate(invalid="ignore", over="ignore"):
        ok = np.abs(a) <= limit if limit is not None else np.isfinite(a)  # NaN fails the comparison too
    if ok.all():
        return
    bad = ~ok.all(axis=1)
    if bad.any():
        what = "a NaN or infinite value" if limit is None else f"a NaN, infinite or huge (beyond {limit:g}) value".replace("e+", "e")
        raise OclgiError(f"query point {int(np.argmax(bad))}: {name} has {what} ({int(bad.sum())} such points)")


@dataclass
class QueryPoints:
    positions: np.ndarray  # (n, 4) float32, w = tri (int bits)
    normals: np.ndarray  # (n, 4) float32
    barys: np.ndarray  # (n, 2) float32
    kind: str = "points"
    shape: tuple | None = None  # (height, width) for camera points
    # (n, 4) float32: the weight each point's radiance is seen with (a
    # camera path through mirrors and glass, kernels/camera.cl); None: 1
    weights: np.ndarray | None = None
    # camera points: how many images of (height / samples) rows are stacked
    # (a render's samples per pixel, ``stack``)
    samples: int = 1

    def __post_init__(self):
        pos = _array(self.positions, "positions", (3, 4), None)
        n = len(pos)
        nrm = _array(self.normals, "normals", (3, 4), n)
        bary = _array(self.barys, "barycentrics", (2,), n)
        xyz = pos[:, :3]
        if pos.dtype == np.float32 and pos.shape[1] == 4:
            tri = pos[:, 3].view(np.int32)
        elif pos.shape[1] == 4:
            w = pos[:, 3].astype(np.float64)
            whole = np.isfinite(w) & (w == np.round(w)) & (np.abs(w) < 2**31)
            if not whole.all():
                raise OclgiError(f"query point {int(np.argmax(~whole))}: positions' 4th column (the triangle "
                                 f"id) must be an integer, got {w[np.argmax(~whole)]!r}")
            tri = w.astype(np.int32)
        else:
            tri = np.full(n, -1, np.int32)
        _finite_rows(xyz, "position", MAX_COORDINATE)
        bad = tri < -1
        if bad.any():
            i = int(np.argmax(bad))
            raise OclgiError(f"query point {i}: triangle id {int(tri[i])} is neither -1 (none) nor a triangle's index")
        _finite_rows(nrm, "normal")
        _finite_rows(bary, "barycentric")
        # squared lengths in the arrays' own precision: no float64 copy of
        # a camera's millions of normals (finite ones: checked above)
        n3 = nrm[:, :3]
        length = np.sqrt(np.einsum("ij,ij->i", n3, n3))
        # A zero normal is how the camera marks a pixel that sees nothing: no
        # estimator counts anything there (arrays made first and filled
        # later start so too); any other normal is a unit vector.
        unit = (np.abs(length - 1.0) <= NORMAL_TOLERANCE) | (length == 0)
        if not unit.all():
            i = int(np.argmax(~unit))
            raise OclgiError(f"query point {i}: its normal has length {length[i]:.6g}, not 1 "
                             f"({int((~unit).sum())} such points; oclgi.query_points normalises them)")
        if pos.dtype != np.float32 or pos.shape[1] != 4:
            packed = np.empty((n, 4), np.float32)
            packed[:, :3] = xyz
            packed[:, 3] = tri.view(np.float32)
            pos = packed
        if nrm.dtype != np.float32 or nrm.shape[1] != 4:
            packed = np.zeros((n, 4), np.float32)
            packed[:, :nrm.shape[1]] = nrm
            nrm = packed
        self.positions = np.ascontiguousarray(pos)
        self.normals = np.ascontiguousarray(nrm, np.float32)
        self.barys = np.ascontiguousarray(bary, np.float32)
        if self.weights is not None:
            wt = _array(self.weights, "weights", (4,), n)
            _finite_rows(wt, "weight")
            if (wt < 0).any():
                raise OclgiError("query points: weights must be >= 0")
            self.weights = np.ascontiguousarray(wt, np.float32)
        if not isinstance(self.kind, str):
            raise OclgiError(f"query points: kind must be a string, got {self.kind!r}")
        if self.shape is not None:
            try:
                h, w = (int(x) for x in self.shape)
            except (TypeError, ValueError):
                raise OclgiError(f"query points: shape must be (height, width), got {self.shape!r}") from None
            if h < 0 or w < 0 or h * w != n:
                raise OclgiError(f"query points: shape {self.shape!r} does not hold {n} points")
            self.shape = (h, w)
        if isinstance(self.samples, bool) or not isinstance(self.samples, (int, np.integer)) or self.samples < 1 \
                or (self.shape is not None and self.shape[0] % self.samples):
            raise OclgiError(f"query points: samples must be a whole number of stacked images of shape "
                             f"{self.shape!r}, got {self.samples!r}")
        self.samples = int(self.samples)

    def check_triangles(self, n_triangles: int, what: str = "the scene") -> QueryPoints:
        """These points, checked for use with a scene of ``n_triangles``: the
        arrays still of the layout the device reads (they may have been
        reassigned since construction) and every triangle id -1 or below
        ``n_triangles`` (a kernel reads the triangle's data by it)."""
        for name, a, width in (("positions", self.positions, 4), ("normals", self.normals, 4),
                               ("barycentrics", self.barys, 2)):
            if not (isinstance(a, np.ndarray) and a.dtype == np.float32 and a.shape == (len(self.positions), width)
                    and a.flags.c_contiguous):
                raise OclgiError(f"query points: {name} must be a C-contiguous (n, {width}) float32 array "
                                 f"(make a new QueryPoints to convert one)")
        tri = self.tri
        bad = (tri < -1) | (tri >= n_triangles)
        if bad.any():
            i = int(np.argmax(bad))
            raise OclgiError(f"query point {i}: triangle id {int(tri[i])} is out of range for {what} "
                             f"({n_triangles} triangles; -1 for none) ({int(bad.sum())} such points)")
        return self

    def __len__(self):
        return len(self.positions)

    def copy(self) -> "QueryPoints":
        return QueryPoints(self.positions.copy(), self.normals.copy(), self.barys.copy(), self.kind, self.shape,
                           None if self.weights is None else self.weights.copy(), self.samples)

    def subset(self, index) -> "QueryPoints":
        """The points ``index`` (copies), as a flat set of the same kind.
        Rows of checked points: not checked again (a camera session takes
        one on every move)."""
        out = object.__new__(QueryPoints)
        out.positions, out.normals, out.barys = self.positions[index], self.normals[index], self.barys[index]
        out.kind, out.shape, out.samples = self.kind, None, 1
        out.weights = None if self.weights is None else self.weights[index]
        return out

    def reshaped(self, shape) -> "QueryPoints":
        """These points (not copied) as an image of ``shape`` = (height, width)."""
        return QueryPoints(self.positions, self.normals, self.barys, self.kind, shape, self.weights)

    def weights4(self) -> np.ndarray:
        """(n, 4) float32 weights, ones when the points have none."""
        return self.weights if self.weights is not None else np.ones((len(self), 4), np.float32)

    @property
    def tri(self) -> np.ndarray:
        return self.positions[:, 3].view(np.int32)

    @property
    def xyz(self) -> np.ndarray:
        return self.positions[:, :3]


def pack(p, n, tri=None, barys=None, kind="points") -> QueryPoints:
    m = len(p)
    pos = np.zeros((m, 4), np.float32)
    pos[:, :3] = p
    pos[:, 3] = (np.full(m, -1, np.int32) if tri is None else np.asarray(tri, np.int32)).view(np.float32)
    nrm = np.zeros((m, 4), np.float32)
    nrm[:, :3] = n
    b = np.zeros((m, 2), np.float32) if barys is None else np.asarray(barys, np.float32)
    return QueryPoints(pos, nrm, b, kind)


def real_array(value, name: str) -> np.ndarray:
    """``value`` as a float64 array if it holds real numbers (not bools,
    complex numbers, strings or objects, which a cast would turn into numbers
    silently or fail on with numpy's own message)."""
    try:
        a = np.asarray(value)
    except ValueError:  # ragged rows
        raise OclgiError(f"{name} must be an (n, 3) array of numbers, got rows of different lengths") from None
    if a.dtype.kind not in "iuf":
        raise OclgiError(f"{name} must be an array of real numbers, got dtype {a.dtype}")
    return a.astype(np.float64)


def stack(images: list) -> QueryPoints:
    """Camera points of several images of one size (a render's samples per
    pixel), one image after the other: shape (len * height, width)."""
    h, w = images[0].shape
    if any(im.shape != (h, w) for im in images):
        raise OclgiError("stack: the images of points differ in size")
    weights = None if all(im.weights is None for im in images) else np.concatenate([im.weights4() for im in images])
    return QueryPoints(np.concatenate([im.positions for im in images]), np.concatenate([im.normals for im in images]),
                       np.concatenate([im.barys for im in images]), kind=images[0].kind, shape=(len(images) * h, w),
                       weights=weights, samples=len(images))


def from_arrays(points, normals) -> QueryPoints:
    """User points: (n, 3) positions and (n, 3) normals, validated.

    Normals are normalised; a zero, NaN or infinite normal or position is an
    error that names the first offending row.
    """
    p, n = real_array(points, "points"), real_array(normals, "normals")
    if p.ndim != 2 or p.shape[1] != 3 or n.shape != p.shape:
        raise OclgiError(f"points and normals must both be (n, 3) arrays, got {p.shape} and {n.shape}")
    if len(p) == 0:
        raise OclgiError("no query points given")
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        raise OclgiError(f"query point {int(np.argmax(bad))} has a NaN or infinite coordinate ({int(bad.sum())} such points)")
    length = np.linalg.norm(n, axis=1)
    bad = ~np.isfinite(length) | ~(length > 1e-12)
    if bad.any():
        raise OclgiError(f"query point {int(np.argmax(bad))} has a zero, NaN or infinite normal ({int(bad.sum())} such points)")
    return pack(p, n / length[:, None])


def from_file(path) -> QueryPoints:
    """Points from ``.npy`` ((n, 6): x y z nx ny nz) or ``.csv`` (the same columns, optional header).

    CSV fields are separated by commas (or whitespace); blank lines and lines
    starting with ``#`` are skipped; a first line that is not numbers is a
    header. A malformed line is an error naming it.
    """
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        raise OclgiError(f"points file not found: {path}")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        from .io import read_npy

        a = read_npy(path, "points").astype(np.float64)
    elif suffix == ".csv":
        from .io import read_csv

        a = read_csv(path, "points", (6,), "x,y,z,nx,ny,nz")
    else:
        raise OclgiError(f"{path}: points must be a .npy or .csv file")
    if a.ndim != 2 or a.shape[1] != 6:
        raise OclgiError(f"{path}: expected n rows of 6 columns (x y z nx ny nz), got shape {a.shape}")
    if len(a) == 0:
        raise OclgiError(f"{path}: no points")
    return from_arrays(a[:, :3], a[:, 3:])


def vertex_points(scene) -> QueryPoints:
    """One query per mesh vertex used by a triangle; normal = area-weighted mean."""
    faces = scene.faces
    v = scene.vertices[faces]
    fn = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])  # length = 2 * area
    acc = np.zeros_like(scene.vertices)
    for k in range(3):
        np.add.at(acc, faces[:, k], fn)
    used = np.zeros(len(scene.vertices), bool)
    used[faces.ravel()] = True
    length = np.linalg.norm(acc, axis=1)
    # A vertex whose normals cancel (thin two-sided sheets) keeps its first face's normal.
    tri = np.full(len(scene.vertices), -1, np.int64)
    corner = np.zeros(len(scene.vertices), np.int64)
    for k in (2, 1, 0):
        tri[faces[:, k]] = np.arange(len(faces))
        corner[faces[:, k]] = k
    flat = used & ~(length > 1e-30)
    acc[flat] = fn[tri[flat]]
    length[flat] = np.linalg.norm(acc[flat], axis=1)
    ids = np.nonzero(used)[0]
    barys = np.zeros((len(ids), 2), np.float32)
    barys[corner[ids] == 1, 0] = 1.0
    barys[corner[ids] == 2, 1] = 1.0
    q = pack(scene.vertices[ids], acc[ids] / length[ids, None], tri[ids], barys, kind="vertices")
    q.vertex_ids = ids
    return q
