"""Writing results: images through OpenImageIO, arrays as .npy or .csv.

Every file is written under a temporary name in the target folder and
renamed into place, so a failed or interrupted run never leaves a partial
output file (nor the temporary one). :func:`write_images` writes several
files all or nothing (a render's EXR and PNG).
"""

from __future__ import annotations

import os
import tempfile
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np

from .errors import OclgiError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_output(path) -> Path:
    """Fail early (before any work) when ``path`` can never be written."""
    path = Path(path)
    if path.is_dir():
        raise OclgiError(f"cannot write {path}: it is a folder")
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise OclgiError(f"cannot write {path}: {parent} is not a folder")
    return path


@contextmanager
def atomic_path(path: Path):
    """Yield a temporary path beside ``path`` (same suffix); rename on success.

    The file gets the permissions a plain ``open`` would give it (0666 less
    the umask), not mkstemp's 0600. OS errors become an :class:`OclgiError`.
    """
    path = Path(path)
    check_output(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OclgiError(f"cannot create output folder {path.parent}: {exc.strerror}") from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:
        raise OclgiError(f"cannot write {path}: {exc.strerror}") from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())
    finally:
        os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise OclgiError(f"cannot write {path}: {exc.strerror or exc}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_image_file(tmp: Path, path: Path, pixels: np.ndarray) -> None:
    """Write an image to ``tmp`` (a temporary name from :func:`atomic_path`; ``path``
    names it in errors): the one OpenImageIO writer of every image oclgi makes."""
    import OpenImageIO as oiio

    h, w, c = pixels.shape
    fmt = oiio.FLOAT if pixels.dtype == np.float32 else oiio.UINT8
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        raise OclgiError(f"cannot write {path}: {oiio.geterror()}")
    spec = oiio.ImageSpec(w, h, c, fmt)
    # No time stamp (OpenEXR's writer adds one unless told otherwise): the
    # same run gives the same bytes, so renders can be compared with cmp.
    spec.attribute("DateTime", "")
    if path.suffix.lower() == ".exr":
        spec.attribute("compression", "zip")
    ok = out.open(str(tmp), spec) and out.write_image(np.ascontiguousarray(pixels))
    err = out.geterror()
    out.close()
    if not ok:
        raise OclgiError(f"cannot write {path}: {err}")


def write_image(path, pixels: np.ndarray) -> Path:
    """Write an (H, W, C) image: float32 for EXR (linear), uint8 for PNG."""
    path = Path(path)
    with atomic_path(path) as tmp:
        write_image_file(tmp, path, pixels)
    return path


def write_images(images: dict) -> list[Path]:
    """Write several images ``{path: pixels}``, all or nothing.

    Every image is written to its temporary file first; only when all are
    complete are they renamed into place.
    """
    paths = [Path(p) for p in images]
    for p in paths:
        check_output(p)
    with ExitStack() as stack:
        for p, pixels in zip(paths, images.values()):
            tmp = stack.enter_context(atomic_path(p))
            write_image_file(tmp, p, pixels)
    return paths


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


def write_array_text(path, columns: list[str], rows) -> Path:
    """A CSV table with a header line (e.g. a per-frame timing log)."""
    path = Path(path)
    check_output(path)
    with atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            f.write(",".join(columns) + "\n")
            for r in rows:
                f.write(",".join(f"{v:.6g}" if isinstance(v, float) else str(v) for v in r) + "\n")
    return path
