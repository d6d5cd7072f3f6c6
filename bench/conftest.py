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

import numpy as np
import pytest

from common import box, device, engine


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


def lit_mesh(name, path, light, intensity, *meshes):
    """An engine on a grey mesh file (and ``meshes``) lit by a white point light."""
    return engine({"name": name, "mesh": [{"path": path, "albedo": [0.7, 0.7, 0.7]}, *meshes],
                   "point_light": [{"position": light, "intensity": [intensity] * 3}]})


@pytest.fixture(scope="session")
def cornell():
    return engine("cornell_box.toml")


@pytest.fixture(scope="session")
def bunny():
    return lit_mesh("bunny", "stanford-bunny/bun_zipper.ply", [0.0, 0.3, 0.2], 1.0)


@pytest.fixture(scope="session")
def bunny_in_box(bunny):
    # The bunny is 0.15 tall, sitting at y = 0.033: scale it to 1.5 on the
    # floor of a 3 x 3 x 3 box. Reuse the loaded arrays (the PLY is slow to parse).
    s = bunny.scene
    verts = s.vertices * 10.0 + np.array([0.0, -0.33, 0.0])
    box_v, box_f = box((-1.5, 0.0, -1.5), (1.5, 3.0, 1.5))
    # Light quad 1 x 1 just under the ceiling, normal (0, -1, 0): it emits downwards.
    light_v = np.array([(-0.5, 2.95, -0.5), (0.5, 2.95, -0.5), (0.5, 2.95, 0.5), (-0.5, 2.95, 0.5)])
    return engine({
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
    return lit_mesh("sponza", "sponza-dabrovic/sponza.zip", [0.0, 6.0, 0.0], 50.0)


_LOADAVG_AT_START = list(os.getloadavg())  # this file is read as the session starts


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


def _version(pkg):
    try:
        return importlib.metadata.version(pkg)
    except importlib.metadata.PackageNotFoundError:
        return None


def pytest_benchmark_update_machine_info(config, machine_info):
    dev = device()
    machine_info.update(opencl_device=dev.name, opencl_platform=dev.platform.version,
                        opencl_compute_units=dev.max_compute_units, cpu_count=os.cpu_count(),
                        loadavg_at_start=_LOADAVG_AT_START,
                        **{f"{pkg}_version": _version(pkg) for pkg in ("oclgi", "pyopencl", "numpy", "embreex")},
                        loadavg_at_end=os.getloadavg())
