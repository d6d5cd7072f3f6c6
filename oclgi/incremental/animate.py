"""Animations: an object moved along a path, the illumination updated
incrementally each frame (a camera :class:`oclgi.Session`).

Path specifications (relative to where the scene file put the object):

    line:DX,DY,DZ        a straight move by that offset over the frames
    orbit:R[,TURNS]      a circle of radius R about the start, in the XZ plane
    FILE.csv | FILE.npy  keyframes, one per row: x y z (a translation), or
                         x y z angle (plus a rotation about Y, degrees),
                         interpolated linearly over the frames; or 16
                         columns, one row-major 4x4 matrix per frame
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import OclgiError
from ..io import read_csv, read_npy
from ..params import MAX_LENGTH


def _translate_rotate(x, y, z, degrees=0.0) -> np.ndarray:
    a = math.radians(degrees)
    m = np.eye(4)
    m[0, 0], m[0, 2], m[2, 0], m[2, 2] = math.cos(a), math.sin(a), -math.sin(a), math.cos(a)
    m[:3, 3] = [x, y, z]
    return m


def _numbers(text: str, where: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise OclgiError(f"{where}: expected comma-separated numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in vals):
        raise OclgiError(f"{where}: numbers must be finite, got {text!r}")
    return vals


def _matrix_problem(m: np.ndarray) -> str | None:
    """Why a row-major 4x4 pose cannot place an object, or None."""
    if not np.allclose(m[3], [0, 0, 0, 1], rtol=0, atol=1e-9):
        return f"has the last row {m[3].tolist()}, not 0,0,0,1 (a pose cannot be projective)"
    linear = m[:3, :3]
    # Singular (a zero scale flattens the object): tested relative to the
    # matrix's own size, so a uniform small scale is still fine.
    size = np.abs(linear).max()
    if size == 0 or abs(np.linalg.det(linear)) <= 1e-9 * size ** 3:
        return "is singular (a zero scale would flatten the object)"
    return None


def _frame_stem(f: int) -> str:
    return f"frame_{f:04d}"


def output_names(frames: int, write_exr: bool = False) -> list[str]:
    """The files :func:`animate` writes into its folder."""
    exts = (".png", ".exr") if write_exr else (".png",)
    return [_frame_stem(f) + ext for f in range(frames) for ext in exts] + ["timing.csv"]


def poses(spec: str, frames: int) -> list[np.ndarray]:
    """The object's 4x4 pose at each of ``frames`` frames, each within the
    coordinates the device holds (float32, to 1e18)."""
    out = _poses(spec, frames)
    for f, m in enumerate(out):
        if np.abs(m).max() > MAX_LENGTH:
            raise OclgiError(f"--path {spec}: frame {f}'s pose moves the object beyond {MAX_LENGTH:.0e}, "
                             f"past what the device's float32 coordinates hold")
    return out


def _poses(spec: str, frames: int) -> list[np.ndarray]:
    if frames < 1:
        raise OclgiError(f"--frames must be at least 1, got {frames}")
    s = np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)
    if spec.startswith("line:"):
        d = _numbers(spec[5:], "--path line")
        if len(d) != 3:
            raise OclgiError("--path line:DX,DY,DZ takes 3 numbers")
        return [_translate_rotate(*(t * np.asarray(d))) for t in s]
    if spec.startswith("orbit:"):
        v = _numbers(spec[6:], "--path orbit")
        if len(v) not in (1, 2) or v[0] <= 0:
            raise OclgiError("--path orbit:R[,TURNS] takes a radius > 0 and optionally a number of turns")
        turns = v[1] if len(v) == 2 else 1.0
        return [_translate_rotate(v[0] * (math.cos(2 * math.pi * turns * t) - 1), 0.0,
                                  v[0] * math.sin(2 * math.pi * turns * t)) for t in s]
    path = Path(spec)
    if not path.is_file():
        raise OclgiError(f"--path {spec!r}: not line:..., orbit:... or an existing .csv/.npy file")
    try:
        if path.suffix.lower() == ".npy":
            keys = read_npy(path, "keyframes")
        elif path.suffix.lower() == ".csv":
            keys = read_csv(path, "keyframes", (3, 4, 16), "x,y,z[,angle] or a 4x4 matrix's 16 numbers")
        else:
            raise OclgiError(f"--path {path}: keyframes must be a .csv or .npy file")
    except ValueError as exc:
        raise OclgiError(f"--path {path}: cannot read keyframes ({exc})") from None
    keys = np.asarray(keys, dtype=np.float64)
    if keys.ndim != 2 or keys.shape[1] not in (3, 4, 16) or len(keys) == 0 or not np.isfinite(keys).all():
        raise OclgiError(f"--path {path}: expected rows of 3, 4 or 16 finite numbers, got shape {keys.shape}")
    if keys.shape[1] == 16:
        if len(keys) != frames:
            raise OclgiError(f"--path {path}: {len(keys)} matrices for {frames} frames")
        matrices = [k.reshape(4, 4) for k in keys]
        for row, m in enumerate(matrices, 1):
            problem = _matrix_problem(m)
            if problem:
                raise OclgiError(f"--path {path}: the matrix of row {row} {problem}")
        return matrices
    u = np.linspace(0, len(keys) - 1, frames) if frames > 1 else np.zeros(1)
    cols = [np.interp(u, np.arange(len(keys)), keys[:, c]) for c in range(keys.shape[1])]
    return [_translate_rotate(*(c[i] for c in cols)) for i in range(frames)]


def _write_frame(stage: Path, f: int, radiance, pixels, write_exr: bool) -> None:
    from ..io import write_images

    stem = stage / _frame_stem(f)
    images = {stem.with_suffix(".png"): pixels}
    if write_exr:
        images[stem.with_suffix(".exr")] = radiance
    write_images(images, sync=False)  # the staged folder flushes them all at its end


def frame_paths(out_dir: Path, frames: int) -> list[Path]:
    """The PNG frames ``animate`` wrote into ``out_dir``, in order."""
    return [Path(out_dir) / (_frame_stem(f) + ".png") for f in range(frames)]


def animate(session, name: str, spec: str, frames: int, out_dir: Path, exposure: float = 1.0,
            write_exr: bool = False, progress=None) -> list[dict]:
    """Move ``name`` along the path, write one PNG (and EXR) per frame and a
    per-frame timing log (``timing.csv``); returns the log rows.

    The files are made in a hidden temporary folder (beside ``out_dir``, or
    inside it when it exists) and moved into it at the end: a run that fails
    part-way adds no frame to it.
    """
    from ..io import staged_folder, write_array_text

    rows = []
    path = poses(spec, frames)
    with staged_folder(out_dir) as stage:
        for f, pose in enumerate(path):
            stats = session.move(name, pose)
            _write_frame(stage, f, *session.render(exposure), write_exr)
            rows.append({"frame": f, "paths": stats.paths, "segments_removed": stats.segments_removed,
                         "segments_added": stats.segments_added, "points": stats.points,
                         **{f"{k}_s": v for k, v in stats.seconds.items()}})
            if progress:
                progress(f, rows[-1])
        keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
        write_array_text(stage / "timing.csv", keys, [[r.get(k, 0.0) for k in keys] for r in rows], sync=False)
    return rows


def animate_light(reuse, out_dir: Path, exposure: float = 1.0, write_exr: bool = False, progress=None,
                  **estimate_args) -> list[dict]:
    """One PNG (and EXR) per light position of ``reuse`` (an
    :class:`oclgi.tracing.light_reuse.LightReuse`: the paths of every
    position traced once, each frame re-weighted) and ``timing.csv``, as
    :func:`animate` writes for a moved object; returns the log rows (frame
    0's carries the store's trace and weights too). ``estimate_args``: the
    estimator's (method, radius, options)."""
    import time

    from ..io import staged_folder, write_array_text

    engine = reuse.engine
    t0 = time.perf_counter()
    points = engine.camera_points()
    estimator = reuse.estimator(points, **estimate_args)
    setup = time.perf_counter() - t0
    rows = []
    with staged_folder(out_dir) as stage:
        for f in range(reuse.frames):
            t1 = time.perf_counter()
            est = reuse.estimate(f, estimator)
            t2 = time.perf_counter()
            radiance, pixels = engine.shade(points, est.device_irradiance, exposure)
            t3 = time.perf_counter()
            _write_frame(stage, f, radiance, pixels, write_exr)
            rows.append({"frame": f, "paths": reuse.n_paths,
                         "trace_s": reuse.seconds["trace"] if f == 0 else 0.0,
                         "weights_s": reuse.seconds["weights"] if f == 0 else 0.0,
                         "setup_s": setup if f == 0 else 0.0,
                         "reuse_s": est.stats.seconds["frame"], "resolve_s": est.stats.seconds["resolve"],
                         "shade_s": t3 - t2, "total_s": t3 - t1})
            if progress:
                progress(f, rows[-1])
        keys = list(rows[0])
        write_array_text(stage / "timing.csv", keys, [[r[k] for k in keys] for r in rows], sync=False)
    return rows
