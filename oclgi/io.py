"""Writing results: images through OpenImageIO, arrays as .npy or .csv.

Every file is written under a temporary name in the target folder and
renamed into place, so a failed or interrupted run never leaves a partial
output file.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import OclgiError


@contextmanager
def atomic_path(path: Path):
    """Yield a temporary path beside ``path`` (same suffix); rename on success."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OclgiError(f"cannot create output folder {path.parent}: {exc.strerror}") from None
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_image(path, pixels: np.ndarray) -> Path:
    """Write an (H, W, C) image: float32 for EXR (linear), uint8 for PNG."""
    import OpenImageIO as oiio

    path = Path(path)
    h, w, c = pixels.shape
    fmt = oiio.FLOAT if pixels.dtype == np.float32 else oiio.UINT8
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise OclgiError(f"cannot write {path}: {oiio.geterror()}")
        spec = oiio.ImageSpec(w, h, c, fmt)
        if path.suffix.lower() == ".exr":
            spec.attribute("compression", "zip")
        ok = out.open(str(tmp), spec) and out.write_image(np.ascontiguousarray(pixels))
        err = out.geterror()
        out.close()
        if not ok:
            raise OclgiError(f"cannot write {path}: {err}")
    return path


def read_image(path) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OclgiError(f"cannot read {path}: {oiio.geterror()}")
    try:
        return inp.read_image()
    finally:
        inp.close()


def write_array(path, values: np.ndarray, points=None) -> Path:
    """Irradiance per point: ``.npy`` (n, 3) float64, or ``.csv`` with the points' columns."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".csv"):
        raise OclgiError(f"{path}: output must end in .npy or .csv")
    values = np.asarray(values, dtype=np.float64)
    with atomic_path(path) as tmp:
        if suffix == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, values)
        else:
            cols = ["E_r", "E_g", "E_b"]
            data = values
            if points is not None:
                cols = ["x", "y", "z", "nx", "ny", "nz"] + cols
                data = np.hstack([points.positions[:, :3], points.normals[:, :3], values])
            np.savetxt(tmp, data, delimiter=",", header=",".join(cols), comments="", fmt="%.9g")
    return path
