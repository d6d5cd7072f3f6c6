"""The host-side scene: triangles, materials, emitters, camera and settings.

A scene is built from a description (a TOML file or the same structure as a
Python dict, see :mod:`oclgi.scene.description`). Geometry is validated here:
non-finite vertices are an error, degenerate triangles (each judged by its
own shape, :mod:`oclgi.scene.degenerate`) are dropped with a warning that
counts them, a scene without any emitter is an error.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..accel.boxes import column_bounds
from ..errors import OclgiError, OclgiWarning  # noqa: F401  (oclgi.scene.scene.OclgiWarning, as it always was)
from ..params import MAX_LENGTH, RunParams
from . import lights as lights_mod
from .degenerate import degenerate_triangles
from .materials import DARK_GLASS, Material
from .lights import PointLight  # noqa: F401  (oclgi.scene.scene.PointLight, as it always was)


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) the area of each face of ``faces`` into ``vertices``."""
    v = np.asarray(vertices)[faces]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


@dataclass
class SceneObject:
    """A group of triangles that moves as one (an instance over its own BVH).

    Object 0 holds the static geometry when there is any; each mesh marked
    ``movable`` is an object of its own, named for ``move`` calls.
    """

    name: str
    movable: bool = False


@dataclass
class Camera:
    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 40.0  # vertical, degrees
    width: int = 256
    height: int = 256

    def frame(self):
        """(eye, forward, right, up), right/up scaled to the image plane's half-extents."""
        eye = np.asarray(self.position, dtype=np.float64)
        fwd = np.asarray(self.look_at, dtype=np.float64) - eye
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, np.asarray(self.up, dtype=np.float64))
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        half_h = math.tan(math.radians(self.fov) / 2.0)
        half_w = half_h * self.width / self.height
        return eye, fwd, right * half_w, up * half_h


MAX_COORDINATE = MAX_LENGTH  # squared lengths stay finite in float32 (params.MAX_LENGTH)


# A corner normal further than this from its triangle's own normal does not
# describe that triangle's surface (a hard edge the file did not split, a
# sheet whose two sides share vertices): such a triangle stays flat. Within
# it, an interpolated normal stays within 60 degrees too, so a disc is
# lifted by at most d sin(60) (oclgi/scene/shading_normals.py).
MAX_SHADING_ANGLE = 60.0  # degrees


def _corner_normals(normals, faces_normals: np.ndarray, name: str) -> np.ndarray | None:
    """Vertex normals of the corners as unit float64 vectors on the side of
    the triangle's own normal (``faces_normals``; a file whose normals all
    oppose its winding is turned round); a triangle with a corner missing
    (NaN), non-finite, of zero length or beyond MAX_SHADING_ANGLE of the
    triangle's normal keeps its geometric normal (all three NaN). None when
    no triangle has a full set."""
    vn = np.asarray(normals, np.float64)
    n_faces = len(faces_normals)
    if vn.shape != (n_faces, 3, 3):
        raise OclgiError(f"{name}: tri_vertex_normals must be (F, 3, 3) corner normals, got {vn.shape}")
    with np.errstate(invalid="ignore", divide="ignore"):
        length = np.linalg.norm(vn, axis=2, keepdims=True)
        unit = vn / length
        cos = np.einsum("fkj,fj->fk", unit, faces_normals)
        side = np.where(np.nansum(cos, axis=1) < 0, -1.0, 1.0)
        full = (np.isfinite(length) & (length > 1e-12)).all(axis=(1, 2))
        full &= (cos * side[:, None] >= np.cos(np.radians(MAX_SHADING_ANGLE))).all(axis=1)
    if not full.any():
        return None
    out = np.full_like(vn, np.nan)
    out[full] = unit[full] * side[full, None, None]
    return out


@dataclass
class Scene:
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int64
    tri_material: np.ndarray  # (F,) int64 into materials
    materials: list[Material]
    point_lights: list[PointLight] = field(default_factory=list)
    camera: Camera | None = None
    settings: RunParams = field(default_factory=RunParams)  # the run's defaults (radius None: 1% of the diagonal)
    name: str = "scene"
    tri_object: np.ndarray | None = None  # (F,) int64 into objects; None: one static object
    objects: list[SceneObject] = field(default_factory=lambda: [SceneObject("static")])
    load_seconds: float = 0.0  # reading the scene and its meshes (load_file, load_dict)
    tri_uv: np.ndarray | None = None  # (F, 3, 2) texture coordinates of the corners (textured scenes)
    tri_colour: np.ndarray | None = None  # (F, 3, 3) linear RGB of the corners (vertex colours), NaN: none
    # spot, sun and sky lights (oclgi.scene.lights); last, so that positional fields keep their places
    lights: list = field(default_factory=list)
    # (F, 3, 3) unit vertex normals of the corners (shading normals: OBJ vn,
    # glTF/PLY normals), NaN for a triangle without a full set; None: none
    tri_vertex_normals: np.ndarray | None = None
    # said when ``camera`` is used: it is a default (a trimesh Scene's without one), not the scene's own
    camera_note: str | None = None

    def __post_init__(self):
        if self.tri_object is None:
            self.tri_object = np.zeros(len(self.faces), np.int64)
        self._validate()

    def object_ranges(self) -> np.ndarray:
        """(n_objects, 2): each object's contiguous run [start, end) of triangles."""
        ids = np.arange(len(self.objects))
        return np.stack([np.searchsorted(self.tri_object, ids, "left"),
                         np.searchsorted(self.tri_object, ids, "right")], axis=1)

    def object_id(self, name: str) -> int:
        for i, o in enumerate(self.objects):
            if o.name == name and o.movable:
                return i
        movable = [o.name for o in self.objects if o.movable]
        raise OclgiError(f"no movable object named {name!r} (movable: {movable or 'none'})")

    # -- derived geometry -------------------------------------------------
    @property
    def n_triangles(self) -> int:
        return len(self.faces)

    def bounds(self):
        return column_bounds(self.vertices)

    @property
    def diagonal(self) -> float:
        lo, hi = self.bounds()
        return float(np.linalg.norm(hi - lo))

    def triangle_areas(self) -> np.ndarray:
        return triangle_areas(self.vertices, self.faces)

    def triangle_normals(self) -> np.ndarray:
        v = self.vertices[self.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    @property
    def radius(self) -> float:
        s = self.settings
        return s.radius if s.radius is not None else 0.01 * self.diagonal

    # -- validation -------------------------------------------------------
    def _validate(self):
        v = np.asarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
            raise OclgiError(f"{self.name}: no vertices")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise OclgiError(f"{self.name}: no triangles")
        if not np.isfinite(v).all():
            bad = int((~np.isfinite(v).all(axis=1)).sum())
            raise OclgiError(f"{self.name}: {bad} vertices have NaN or infinite coordinates")
        if np.abs(v).max() > MAX_COORDINATE:
            raise OclgiError(f"{self.name}: vertex coordinates reach {np.abs(v).max():.3g}; at most "
                             f"{MAX_COORDINATE:.0e} is supported (the device computes in float32)")
        if f.min() < 0 or f.max() >= len(v):
            raise OclgiError(f"{self.name}: face indices out of range")
        self.vertices, self.faces = v, f
        self.tri_material = np.asarray(self.tri_material, dtype=np.int64)
        degenerate = degenerate_triangles(v, f)
        if degenerate.any():
            n_bad = int(degenerate.sum())
            keep = ~degenerate
            self.faces, self.tri_material = self.faces[keep], self.tri_material[keep]
            self.tri_object = np.asarray(self.tri_object)[keep]
            for key in ("tri_uv", "tri_colour", "tri_vertex_normals"):
                if getattr(self, key) is not None:
                    setattr(self, key, np.asarray(getattr(self, key))[keep])
            warnings.warn(f"{self.name}: dropped {n_bad} degenerate triangles (zero area, "
                          "or too thin for the device's float32)", OclgiWarning, stacklevel=3)
            if len(self.faces) == 0:
                raise OclgiError(f"{self.name}: every triangle is degenerate")
        for m in self.materials:
            if not isinstance(m, Material):
                raise OclgiError(f"{self.name}: materials must be oclgi.Material, got {type(m).__name__}")
            m.validate()
            if m.kind in ("dielectric", "rough_dielectric") and max(m.transmission) < DARK_GLASS:
                warnings.warn(f"material {m.name!r}: glass transmitting {max(m.transmission):.3g} of the light "
                              f"(under {DARK_GLASS:g}) renders almost black; transmission = [1, 1, 1] is "
                              "clear glass", OclgiWarning, stacklevel=3)
        lights_mod.validate(self)
        if not isinstance(self.settings, RunParams):  # a RunParams checks its values when made
            raise OclgiError(f"{self.name}: settings must be an oclgi.params.RunParams, "
                             f"got {type(self.settings).__name__}")
        self.tri_object = np.asarray(self.tri_object, dtype=np.int64)
        if self.tri_uv is not None:
            uv = np.asarray(self.tri_uv, np.float64)
            if uv.shape != (len(self.faces), 3, 2):
                raise OclgiError(f"{self.name}: tri_uv must be (F, 3, 2) texture coordinates, got {uv.shape}")
            self.tri_uv = uv
        if self.tri_colour is not None:
            col = np.asarray(self.tri_colour, np.float64)
            if col.shape != (len(self.faces), 3, 3):
                raise OclgiError(f"{self.name}: tri_colour must be (F, 3, 3) corner colours, got {col.shape}")
            if ((col < 0) | (col > 1)).any():
                raise OclgiError(f"{self.name}: vertex colours must lie in [0, 1]")
            self.tri_colour = col
        if self.tri_vertex_normals is not None:
            self.tri_vertex_normals = _corner_normals(self.tri_vertex_normals, self.triangle_normals(), self.name)
        if len(self.tri_object) != len(self.faces) or (np.diff(self.tri_object) < 0).any():
            raise OclgiError(f"{self.name}: triangles must be grouped object by object")
        counts = np.bincount(self.tri_object, minlength=len(self.objects))
        if len(counts) != len(self.objects) or (counts == 0).any():
            raise OclgiError(f"{self.name}: every object needs at least one (non-degenerate) triangle")
        emissive = np.array([max(m.emission) > 0 for m in self.materials], dtype=bool)[self.tri_material]
        for i, o in enumerate(self.objects):
            if o.movable and emissive[self.tri_object == i].any():
                raise OclgiError(f"{self.name}: movable object {o.name!r} emits light; moving lights are not "
                                 "supported yet (they need path reuse, not incremental update)")
        if not self.has_emitter():
            raise OclgiError(f"{self.name}: the scene has no emitter (no emissive material in use and no light)")

    def has_emitter(self) -> bool:
        if lights_mod.has_power(self):
            return True
        emissive = np.array([max(m.emission) > 0 for m in self.materials], dtype=bool)
        return bool(len(self.tri_material) and emissive[self.tri_material].any())

    # -- emitters -----------------------------------------------------------
    def emitters(self):
        """Emissive triangles and the other lights with their power (RGB, watts).

        Returns (kind, tri, p, e1, e2, power) arrays (oclgi.scene.lights.
        emitter_rows has every field of the records); an area light emits
        pi * A * Le on the side of its normal.
        """
        r = lights_mod.emitter_rows(self)
        return r.kind, r.tri, r.p, r.e1, r.e2, r.power
