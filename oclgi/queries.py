"""Query points: where irradiance is estimated.

Three sources: the visible point of each pixel of a camera (computed on the
device by ``kernels/camera.cl``), the mesh vertices (normals averaged over
the adjacent triangles, weighted by area), and arbitrary points with normals
given by the user (sensors, reference positions). Each point carries a unit
normal: DETP counts light arriving on the normal's side.

Layout (float32): positions (n, 4) with w = the triangle under the point as
int bits (-1 when unknown or none), normals (n, 4), barycentrics (n, 2) on
that triangle. Impact Count needs the triangle; DETP does not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import OclgiError


@dataclass
class QueryPoints:
    positions: np.ndarray  # (n, 4) float32, w = tri (int bits)
    normals: np.ndarray  # (n, 4) float32
    barys: np.ndarray  # (n, 2) float32
    kind: str = "points"
    shape: tuple | None = None  # (height, width) for camera points

    def __len__(self):
        return len(self.positions)

    def copy(self) -> "QueryPoints":
        return QueryPoints(self.positions.copy(), self.normals.copy(), self.barys.copy(), self.kind, self.shape)

    def subset(self, index) -> "QueryPoints":
        """The points ``index`` (copies), as a flat set of the same kind."""
        return QueryPoints(self.positions[index], self.normals[index], self.barys[index], self.kind, None)

    @property
    def tri(self) -> np.ndarray:
        return self.positions[:, 3].view(np.int32)

    @property
    def xyz(self) -> np.ndarray:
        return self.positions[:, :3]


def _pack(p, n, tri=None, barys=None, kind="points") -> QueryPoints:
    m = len(p)
    pos = np.zeros((m, 4), np.float32)
    pos[:, :3] = p
    pos[:, 3] = (np.full(m, -1, np.int32) if tri is None else np.asarray(tri, np.int32)).view(np.float32)
    nrm = np.zeros((m, 4), np.float32)
    nrm[:, :3] = n
    b = np.zeros((m, 2), np.float32) if barys is None else np.asarray(barys, np.float32)
    return QueryPoints(pos, nrm, b, kind)


def from_arrays(points, normals) -> QueryPoints:
    """User points: (n, 3) positions and (n, 3) normals, validated.

    Normals are normalised; a zero, NaN or infinite normal or position is an
    error that names the first offending row.
    """
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
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
    return _pack(p, n / length[:, None])


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
        try:
            with open(path, "rb") as f:
                if f.read(6) != b"\x93NUMPY":
                    raise OclgiError(f"{path}: not a .npy file")
            a = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise OclgiError(f"{path}: cannot read points ({exc})") from None
        if not isinstance(a, np.ndarray) or a.dtype.kind not in "iuf":
            raise OclgiError(f"{path}: expected an array of numbers, got {getattr(a, 'dtype', type(a).__name__)}")
        a = a.astype(np.float64)
    elif suffix == ".csv":
        a = _read_csv(path)
    else:
        raise OclgiError(f"{path}: points must be a .npy or .csv file")
    if a.ndim != 2 or a.shape[1] != 6:
        raise OclgiError(f"{path}: expected n rows of 6 columns (x y z nx ny nz), got shape {a.shape}")
    if len(a) == 0:
        raise OclgiError(f"{path}: no points")
    return from_arrays(a[:, :3], a[:, 3:])


def _read_csv(path) -> np.ndarray:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise OclgiError(f"{path}: not a text (CSV) file") from None
    except OSError as exc:
        raise OclgiError(f"{path}: cannot read points ({exc.strerror or exc})") from None
    rows = []
    first = True
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = _fields(line)
        try:
            values = [float(x) for x in fields]
        except ValueError:
            if first and not any(_is_number(x) for x in fields):  # a header
                first = False
                continue
            raise OclgiError(f"{path}:{lineno}: expected 6 numbers (x,y,z,nx,ny,nz), got {raw.strip()!r}") from None
        first = False
        if len(values) != 6:
            raise OclgiError(f"{path}:{lineno}: expected 6 columns (x,y,z,nx,ny,nz), got {len(values)}")
        rows.append(values)
    if not rows:
        raise OclgiError(f"{path}: no points")
    return np.array(rows, dtype=np.float64)


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _fields(line: str) -> list[str]:
    if "," in line:
        return [x.strip() for x in line.split(",")]
    return line.split()


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
    q = _pack(scene.vertices[ids], acc[ids] / length[ids, None], tri[ids], barys, kind="vertices")
    q.vertex_ids = ids
    return q
