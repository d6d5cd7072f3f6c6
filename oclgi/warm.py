"""Filling PoCL's kernel cache before the first real run (``oclgi warm``).

A cold PoCL compiles each program from source (the first build of a process
also loads PoCL's built-in library) and each kernel again at its first
launch: seconds that every first run of a fresh machine would pay. The
make targets' set-up runs ``oclgi warm`` once, so that a user's first render
starts from a filled cache.

What is built is found by running, not by a list kept in sync by hand:
every command's code path runs once on a tiny view of the Cornell box with
the bunny (each estimator, a render plain and with the command's default
estimate, a DETP session and a Photon Map session
with one move each), which builds exactly the programs and defines real
runs use (the bunny's 69k triangles also build its SAH tree on the device,
``accel/bvh_sah_device.py``, as every scene tree of 50,000 triangles or
more). Then every built program is asked for its binaries, which makes
PoCL compile each of its kernels, launched or not, into the cache. Launches
compile the generic version of a kernel (any work-group and grid size,
``cl/device.py``), so a tiny run warms the kernels a large one launches.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from .cl.programs import programs
from .params import METHODS

PHOTONS = 2000
SIDE = 8  # pixels per side of the warm-up views


def warm(device: str | None = None, report=None) -> dict:
    """Build and compile every kernel oclgi's commands use on ``device``.

    ``report(text)`` is called before each step. Returns the number of
    programs and kernels compiled and the seconds it took.
    """
    from . import scene_path
    from .engine import Engine
    from .estimators.render_preset import render_settings
    from .incremental.photon_map_session import PhotonMapSession
    from .incremental.session import Session
    from .scene.description import load_file

    say = report or (lambda text: None)
    t0 = time.perf_counter()
    engine = Engine(load_file(scene_path("cornell_bunny.toml")), device=device, progress=False)
    points = engine.camera_points(width=SIDE, height=SIDE)
    for method in METHODS:
        say(f"estimator {method}")
        engine.irradiance(points, method=method, photons=PHOTONS)
    say("render")
    engine.render(width=SIDE, height=SIDE, photons=PHOTONS)
    say("render, the command's default estimate")  # estimators/render_preset.py: gathering, direct light
    preset = render_settings("detp", {}, False, SIDE, SIDE)
    engine.render(width=SIDE, height=SIDE, photons=PHOTONS, **preset)
    moved = np.eye(4)
    moved[0, 3] = 0.05
    say("DETP session")
    session = Session(engine, camera=engine.view_camera(width=SIDE, height=SIDE), photons=PHOTONS)
    session.move("bunny", moved)
    session.render()
    say("Photon Map session")
    pm = PhotonMapSession(engine, points, photons=PHOTONS)
    pm.move("bunny", moved)
    say("every kernel of every program")
    cache = programs(engine.ctx)
    n_kernels = 0
    built = cache.built()
    for prog in built:
        prog.program.get_info(cl.program_info.BINARIES)  # PoCL compiles all kernels for its binary
        n_kernels += len(prog.kernels)
    engine.queue.finish()
    return {"programs": len(built), "kernels": n_kernels, "seconds": time.perf_counter() - t0}
