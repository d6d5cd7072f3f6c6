"""What the benchmark scripts share: where results go, the machine, timing,
scenes and engines, random surface points, figures."""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np

import oclgi
from oclgi.cl.device import choose_device

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results"
device = choose_device  # the OpenCL device engines run on


def arguments(doc: str, argv=None, **opts) -> argparse.Namespace:
    """The command line's options, a keyword each: --NAME (underscores as
    dashes) with its value as the default and type (False: a flag), or a
    (default, help) pair, or add_argument's own keywords as a dict (and
    ``short``, a one-letter flag); ``quick``, a dict, makes --quick, a smoke
    run, which sets those options."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    quick = opts.get("quick")
    if isinstance(quick, dict):
        opts["quick"] = (False, "a smoke run: " + ", ".join(f"--{k.replace('_', '-')} {v}" for k, v in quick.items()))
    for name, spec in opts.items():
        if not isinstance(spec, dict):
            default, help = spec if isinstance(spec, tuple) else (spec, None)
            spec = dict(action="store_true") if default is False else dict(type=type(default), default=default)
            spec["help"] = help
        short = [spec.pop("short")] if "short" in spec else []
        ap.add_argument(*short, "--" + name.replace("_", "-"), **spec)
    args = ap.parse_args(argv)
    if isinstance(quick, dict) and args.quick:
        vars(args).update(quick)
    return args


def machine_line(dev) -> str:
    """A report's machine line: the OpenCL device, the CPU and the load average now."""
    return (f"Machine: {dev.name.strip()} ({dev.max_compute_units} compute units), "
            f"{platform.processor() or platform.machine()}, load average {os.getloadavg()[0]:.2f}.")


def timed(fn, *args, **kwargs):
    """(wall seconds, result) of ``fn(*args, **kwargs)``."""
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - t0, out


def cpu_timed(fn, *args, **kwargs):
    """(wall seconds, CPU seconds of this process and its threads, result): on a shared machine, the work's cost."""
    c0 = sum(os.times()[:2])
    t, out = timed(fn, *args, **kwargs)
    return t, sum(os.times()[:2]) - c0, out


def cached_pair(path: Path, render, seeds=(0, 1)):
    """(a, b, seconds): ``render(seed)`` for both seeds and the seconds they took,
    from ``path`` when an earlier run left them there (references are slow)."""
    if path.is_file():
        with np.load(path) as z:
            return z["a"], z["b"], float(z["seconds"])
    seconds, (a, b) = timed(lambda: [render(seed) for seed in seeds])
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, a=a, b=b, seconds=seconds)
    return a, b, seconds


def load(desc) -> oclgi.Scene:
    """A scene file (a path or a shipped scene's name) or dict (paths relative to scenes/), the
    files' own warnings silenced (Sponza's zero-area triangle, the Kd of a file's mirror and glass)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", oclgi.OclgiWarning)
        if isinstance(desc, dict):
            return oclgi.load_dict(desc, base_dir=oclgi.scene_path("."))
        return oclgi.load_file(oclgi.scene_path(str(desc)))


def engine(desc) -> oclgi.Engine:
    """An engine, no progress bars, on ``load(desc)`` (or on a loaded scene)."""
    return oclgi.Engine(desc if isinstance(desc, oclgi.Scene) else load(desc), progress=False)


def surface_points(scene, n: int, rng) -> oclgi.QueryPoints:
    """n points uniform over the scene's area, each on a random side of its triangle."""
    areas = scene.triangle_areas()
    tri = rng.choice(len(areas), size=n, p=areas / areas.sum())
    b = rng.dirichlet([1, 1, 1], n)
    p = np.einsum("rk,rkc->rc", b, scene.vertices[scene.faces[tri]])
    nrm = scene.triangle_normals()[tri] * np.where(rng.random(n) < 0.5, 1.0, -1.0)[:, None]
    return oclgi.query_points(p, nrm)


def concat(qs, **kwargs) -> oclgi.QueryPoints:
    """The query points ``qs`` one after another."""
    return oclgi.QueryPoints(*(np.concatenate([getattr(q, a) for q in qs]) for a in ("positions", "normals", "barys")),
                             **kwargs)


def box(lo, hi):
    """(vertices, faces): the 12 triangles of an axis-aligned box."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x, y, z) for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array(v, float), np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])


def figure(rows: int = 1, cols: int = 1, figsize=None, **subplots):
    """(figure, axes) drawn on a canvas of its own, whatever matplotlib's backend."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(rows, cols, **subplots)


def write(name: str, text: str) -> Path:
    """Write ``bench/results/NAME``; its path."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    (path := RESULTS / name).write_text(text)
    return path
