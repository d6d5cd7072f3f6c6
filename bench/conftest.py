"""Fixtures of the benchmarks: the benchmark scenes, and what the machine was.

Every scene is loaded and compiled once per session: loading files and
building BVHs is not what the tracing and ray benchmarks measure (the BVH
build has its own benchmark). Scenes:

- ``cornell``: the shipped Cornell box (36 triangles, area light).
- ``bunny``: the Stanford bunny alone (69k triangles) with a point light,
  which adds no geometry, so oclgi and Embree see exactly the same triangles.
- ``bunny_in_box``: the bunny, scaled up, inside a closed box lit by an area
  light under the ceiling: a real mesh where photon paths end by absorption
  (Russian roulette) or at ``max_depth``, never by escaping.
- ``sponza``: Dabrovic's Sponza atrium (66k triangles) with a point light in
  the atrium; its roof is open, so paths end both ways.

``--bench-scale`` multiplies every workload size (paths, rays, triangles), so
``--bench-scale 0.1`` gives a quick run; the numbers in bench/HISTORY.md use 1.
"""

from __future__ import annotations

import contextlib
import importlib.metadata
import os
import time
import warnings

import numpy as np
import pytest

import oclgi


def pytest_addoption(parser):
    parser.addoption("--bench-scale", type=float, default=1.0,
                     help="multiply the benchmark workload sizes (default 1)")


@pytest.fixture(scope="session")
def scale(request):
    """Workload size for a nominal count n: n * --bench-scale, at least 1000."""
    factor = request.config.getoption("--bench-scale")
    return lambda n: max(1000, int(n * factor))


_TREES = {}


def compiled_with(engine, quality):
    """The engine's scene compiled with the given scene tree (one of
    ``oclgi.accel.bvh_build.QUALITIES``: "sah8b", the default, the binned SAH
    tree in 8-wide nodes with leaf blocks; "sah", the same tree traversed
    binary; "lbvh", the binary Morton tree): the engine's own for its
    default, else built once per session."""
    if engine.compiled.bvh_quality == quality:
        return engine.compiled
    key = (id(engine), quality)
    if key not in _TREES:
        from oclgi.scene.compiled import CompiledScene

        _TREES[key] = CompiledScene(engine.ctx, engine.scene, bvh_quality=quality)
    return _TREES[key]


def _engine(desc) -> oclgi.Engine:
    """An engine on a shipped scene file (its name) or a scene dict."""
    with warnings.catch_warnings():
        # Sponza has one zero-area triangle; the scene drops it with a warning.
        warnings.simplefilter("ignore", oclgi.OclgiWarning)
        if isinstance(desc, str):
            scene = oclgi.load_file(oclgi.scene_path(desc))
        else:
            scene = oclgi.load_dict(desc, base_dir=oclgi.scene_path("."))
    return oclgi.Engine(scene, progress=False)


def _box(lo, hi):
    """The 12 triangles of an axis-aligned box (surfaces are two-sided)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x, y, z) for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return np.array(v, float), np.array(f)


@pytest.fixture(scope="session")
def cornell():
    return _engine("cornell_box.toml")


@pytest.fixture(scope="session")
def bunny():
    return _engine({
        "name": "bunny",
        "mesh": [{"path": "stanford-bunny/bun_zipper.ply", "albedo": [0.7, 0.7, 0.7]}],
        "point_light": [{"position": [0.0, 0.3, 0.2], "intensity": [1.0, 1.0, 1.0]}],
    })


@pytest.fixture(scope="session")
def bunny_in_box(bunny):
    # The bunny is 0.15 tall, sitting at y = 0.033: scale it to 1.5 on the
    # floor of a 3 x 3 x 3 box. Reuse the loaded arrays (the PLY is slow to parse).
    s = bunny.scene
    verts = s.vertices * 10.0 + np.array([0.0, -0.33, 0.0])
    box_v, box_f = _box((-1.5, 0.0, -1.5), (1.5, 3.0, 1.5))
    # Light quad 1 x 1 just under the ceiling, normal (0, -1, 0): it emits downwards.
    light_v = np.array([(-0.5, 2.95, -0.5), (0.5, 2.95, -0.5), (0.5, 2.95, 0.5), (-0.5, 2.95, 0.5)])
    return _engine({
        "name": "bunny_in_box",
        "mesh": [
            {"vertices": verts, "faces": s.faces, "albedo": [0.7, 0.7, 0.7]},
            {"vertices": box_v, "faces": box_f, "albedo": [0.7, 0.7, 0.7]},
            {"vertices": light_v, "faces": [(0, 1, 2), (0, 2, 3)], "albedo": [0.0, 0.0, 0.0],
             "emission": [10.0, 10.0, 10.0]},
        ],
    })


@pytest.fixture(scope="session")
def sponza():
    # Sponza ships without materials: one grey albedo, a point light in the atrium.
    return _engine({
        "name": "sponza",
        "mesh": [{"path": "sponza-dabrovic/sponza.zip", "albedo": [0.7, 0.7, 0.7]}],
        "point_light": [{"position": [0.0, 6.0, 0.0], "intensity": [50.0, 50.0, 50.0]}],
    })


_LOADAVG_AT_START = []


def pytest_sessionstart(session):
    _LOADAVG_AT_START[:] = os.getloadavg()


@pytest.fixture
def cores_used(benchmark):
    """``with cores_used(): ...`` records the CPU time of this process over the
    wall time of the block, i.e. how many cores the timed work really got.
    The machine may be shared: on 2 cores, about 2 means nothing else ran,
    about 1 means another process held a core and the rates are halved."""

    @contextlib.contextmanager
    def meter():
        wall, cpu = time.perf_counter(), time.process_time()
        yield
        benchmark.extra_info["cores_used"] = round((time.process_time() - cpu) / (time.perf_counter() - wall), 2)

    return meter


def pytest_benchmark_update_machine_info(config, machine_info):
    from oclgi.cl.device import choose_device

    dev = choose_device()
    machine_info["opencl_device"] = dev.name
    machine_info["opencl_platform"] = dev.platform.version
    machine_info["opencl_compute_units"] = dev.max_compute_units
    machine_info["cpu_count"] = os.cpu_count()
    machine_info["loadavg_at_start"] = _LOADAVG_AT_START
    for pkg in ("oclgi", "pyopencl", "numpy", "embreex"):
        try:
            machine_info[f"{pkg}_version"] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            machine_info[f"{pkg}_version"] = None
    machine_info["loadavg_at_end"] = os.getloadavg()
