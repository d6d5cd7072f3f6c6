"""oclgi: global illumination by density estimation, on OpenCL.

    import oclgi
    scene = oclgi.load_file("scenes/cornell_box.toml")
    engine = oclgi.Engine(scene)                      # PoCL CPU device by default
    result = engine.render(method="detp", photons=100_000)
    oclgi.save_render(result, "out/cornell_box.exr")  # EXR + PNG
    est = engine.irradiance(points_and_normals)       # (n, 6) array -> (n, 3) irradiance
"""

from pathlib import Path as _Path

from .engine import Engine, Estimate, Render, Stats
from .errors import OclgiError
from .queries import QueryPoints, from_arrays as query_points, from_file as read_points
from .scene.description import load_dict, load_file
from .scene.scene import Camera, Material, OclgiWarning, PointLight, Scene
from .incremental.photon_map_session import PhotonMapSession
from .incremental.session import Session, UpdateStats

__version__ = "0.1.0"


def scene_path(name: str) -> _Path:
    """Path of a scene shipped with oclgi's source tree (``scenes/NAME``)."""
    here = _Path(__file__).resolve().parent.parent / "scenes" / name
    if here.exists():
        return here
    raise OclgiError(f"shipped scene {name!r} not found (scenes/ is part of the source tree)")


def save_render(result: Render, path) -> tuple[_Path, _Path]:
    """Write the linear radiance as EXR and the tone-mapped image as PNG (same stem)."""
    from .io import write_images

    path = _Path(path)
    exr, png = path.with_suffix(".exr"), path.with_suffix(".png")
    write_images({exr: result.radiance, png: result.pixels})  # all or nothing
    return exr, png


__all__ = [
    "Engine", "Estimate", "Render", "Stats", "OclgiError", "OclgiWarning", "QueryPoints",
    "query_points", "read_points", "load_dict", "load_file", "Camera", "Material", "PointLight",
    "Scene", "Session", "PhotonMapSession", "UpdateStats", "scene_path", "save_render", "__version__",
]
