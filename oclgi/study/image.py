"""The image part of the estimator study: oclgi against Mitsuba 3.

:func:`compare_with_mitsuba` renders the scene's camera view with oclgi and
with Mitsuba's path tracer (:mod:`oclgi.study.mitsuba`), compares them
away from geometric edges (:mod:`oclgi.study.image_compare`) and writes, all or
nothing, into ``out_dir``:

    oclgi.exr         oclgi's linear radiance
    mitsuba.exr       Mitsuba's
    error.exr         signed relative error of luminance (oclgi - mitsuba) / mitsuba, 0 where masked
    error.png         the same on a colour ramp (blue: oclgi lower, red: higher), masked pixels grey
    comparison.json   the statistics, the parameters of both runs and their times
"""

from __future__ import annotations

import json
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from . import image_compare
from . import mitsuba as mitsuba_reference
from ..errors import OclgiError
from ..io import write_image_file, atomic_path, check_output
from ..params import RUN_KEYS

FILES = ("oclgi.exr", "mitsuba.exr", "error.exr", "error.png", "comparison.json")


def compare_with_mitsuba(engine, out_dir, spp: int = 256, edge_px: int = 3, width: int | None = None,
                         height: int | None = None, *, mitsuba_seed: int = 0, error_scale: float = 0.2,
                         **estimate_args) -> dict:
    """Render the camera view with oclgi and Mitsuba, compare, write ``out_dir``; return the summary.

    ``estimate_args`` go to ``engine.render`` (method, photons, radius, seed,
    max_depth, estimator options); Mitsuba gets the same camera, resolution
    and matching path length. ``edge_px``: pixels this close to a geometric
    edge are left out of the statistics. ``error_scale``: the relative error
    at full colour in error.png.
    """
    out_dir = Path(out_dir)
    paths = {name: out_dir / name for name in FILES}
    for p in paths.values():
        check_output(p)
    run = engine.run_params(**{k: estimate_args[k] for k in RUN_KEYS if k in estimate_args})
    if not run.count_emitted:
        raise OclgiError("the Mitsuba comparison needs count_emitted = true (Mitsuba has no indirect-only mode)")
    if isinstance(edge_px, bool) or not isinstance(edge_px, (int, np.integer)) or edge_px < 0:
        raise OclgiError(f"edge_px must be an integer >= 0, got {edge_px!r}")
    mi = mitsuba_reference.load_mitsuba()  # fail before the oclgi render when Mitsuba is missing

    t0 = time.perf_counter()
    result = engine.render(width=width, height=height, **estimate_args)
    t_oclgi = time.perf_counter() - t0
    points = result.estimate.points
    h, w = points.shape
    t0 = time.perf_counter()
    reference = mitsuba_reference.render(engine, width=w, height=h, spp=spp, seed=mitsuba_seed,
                                         max_depth=run.max_depth)
    t_mitsuba = time.perf_counter() - t0

    mask = image_compare.edge_mask(points, edge_px, scene=engine.scene)
    cmp = image_compare.compare(result.radiance, reference, mask, scale=error_scale)
    summary = {
        "scene": engine.scene.name,
        "width": w, "height": h, "edge_px": int(edge_px),
        **cmp.summary(),
        "oclgi": {**{k: getattr(run, k) for k in RUN_KEYS}, "segments": result.stats.segments,
                  "seconds": t_oclgi, "device": engine.queue.device.name.strip()},
        "mitsuba": {"version": mi.__version__, "variant": mi.variant(), "integrator": "path",
                    "max_depth": mitsuba_reference.max_depth_for(run.max_depth),
                    "spp": mitsuba_reference.sample_count(spp),
                    "sampler": mitsuba_reference.SAMPLER, "seed": int(mitsuba_seed), "seconds": t_mitsuba},
        "files": list(FILES),
    }
    images = {
        paths["oclgi.exr"]: result.radiance.astype(np.float32),
        paths["mitsuba.exr"]: reference.astype(np.float32),
        paths["error.exr"]: cmp.error[:, :, None],
        paths["error.png"]: cmp.error_rgba,
    }
    # Every file goes to a temporary name first; they are renamed into place
    # only once all are complete, so a failure leaves none of them.
    with ExitStack() as stack:
        for p, pixels in images.items():
            write_image_file(stack.enter_context(atomic_path(p)), p, pixels)
        tmp = stack.enter_context(atomic_path(paths["comparison.json"]))
        tmp.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary
