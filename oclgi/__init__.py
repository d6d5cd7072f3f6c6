"""oclgi: global illumination by density estimation, on OpenCL.

    import oclgi
    scene = oclgi.load_file("scenes/cornell_box.toml")
    engine = oclgi.Engine(scene)                      # PoCL CPU device by default
    result = engine.render(photons=100_000)         # DETP with disc indexing by default
    oclgi.save_render(result, "out/cornell_box.exr")  # EXR + PNG
    est = engine.irradiance(points_and_normals)       # (n, 6) array -> (n, 3) irradiance
"""

import importlib as _importlib
from pathlib import Path as _Path

from .errors import OclgiError

__version__ = "0.1.0"

# The API's names are imported on first use (PEP 562), not with the package:
# the command line (oclgi.cli) imports this package first, and must be able
# to set up its Ctrl-C handling before numpy and pyopencl load.
_LAZY = {
    "Engine": ".engine", "Estimate": ".engine", "Render": ".engine", "Stats": ".engine",
    "QueryPoints": ".queries", "query_points": (".queries", "from_arrays"),
    "read_points": (".queries", "from_file"),
    "load_dict": ".scene.description", "load_file": ".scene.description",
    "Camera": ".scene.scene", "Material": ".scene.scene", "OclgiWarning": ".scene.scene",
    "PointLight": ".scene.scene", "Scene": ".scene.scene",
    "SpotLight": ".scene.lights", "SunLight": ".scene.lights", "SkyLight": ".scene.lights",
    "PhotonMapSession": ".incremental.photon_map_session",
    "Session": ".incremental.session", "UpdateStats": ".incremental.protocol",
    "open_session": ".incremental.open_session", "LightSession": ".incremental.light_session", "IncrementalSession": ".incremental.protocol",
}


def __getattr__(name):
    where = _LAZY.get(name)
    if where is None:
        try:  # a sub-package or module, as ``oclgi.engine`` after ``import oclgi``
            return _importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    module, attr = where if isinstance(where, tuple) else (where, name)
    value = getattr(_importlib.import_module(module, __name__), attr)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


def scene_path(name: str) -> _Path:
    """Path of a scene shipped with oclgi's source tree (``scenes/NAME``)."""
    here = _Path(__file__).resolve().parent.parent / "scenes" / name
    if here.exists():
        return here
    raise OclgiError(f"shipped scene {name!r} not found (scenes/ is part of the source tree)")


def save_render(result: "Render", path) -> tuple[_Path, _Path]:
    """Write the linear radiance as EXR and the tone-mapped image as PNG (same stem)."""
    from .io import write_images

    path = _Path(path)
    exr, png = path.with_suffix(".exr"), path.with_suffix(".png")
    pixels, channels = result.exr_channels()  # RGB, and the layers when the render has them
    write_images({exr: pixels, png: result.pixels}, metadata=result.metadata, channels={exr: channels})
    return exr, png


__all__ = [
    "Engine", "Estimate", "Render", "Stats", "OclgiError", "OclgiWarning", "QueryPoints",
    "query_points", "read_points", "load_dict", "load_file", "Camera", "Material", "PointLight", "SpotLight",
    "SunLight", "SkyLight", "Scene", "Session", "PhotonMapSession", "UpdateStats",
    "open_session", "IncrementalSession", "LightSession", "scene_path", "save_render", "__version__",
]
