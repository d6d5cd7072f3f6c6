"""``oclgi study``: the estimator study from the command line (oclgi/study/run.py).

Every input is checked before any photon is traced, and the report's four
files are written together at the end (all or nothing), so bad input leaves
nothing behind.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ..errors import OclgiError
from ..io import read_npy

DEFAULT_METHODS = ("detp_disc_index", "photon_map", "impact")
DEFAULT_PHOTON_FRACTIONS = (0.1, 1 / 3, 1.0)  # of the scene's photon count: one decade


def _reference(spec: str):
    from . import reference as study_reference

    path = Path(spec)
    if path.suffix.lower() == ".npy":
        if not path.is_file():
            raise OclgiError(f"reference file not found: {path}")
        values = read_npy(path, "reference irradiance")
        if values.ndim not in (1, 2):
            raise OclgiError(f"{path}: expected an (n, 3) or (n,) array of irradiance values")
        return values.astype(np.float64)
    ref = study_reference.parse(spec)
    study_reference.check_available(ref)
    return ref


def _points(spec: str):
    from ..queries import from_file

    if Path(spec).suffix.lower() in (".npy", ".csv"):
        return from_file(spec)
    return spec  # vertices, camera, random:N: checked by oclgi.study.study_points


def _configs(engine, args):
    from .. import params
    from ..estimators import option_names
    from .run import Config

    methods = args.methods or [(m, {}) for m in DEFAULT_METHODS]
    photons = args.photons or sorted({max(1, round(f * engine.scene.settings.photons))
                                      for f in DEFAULT_PHOTON_FRACTIONS})
    shared = dict(args.option)
    used = set()
    configs = []
    for method, own in methods:
        # an -O option goes to every method that takes it (extension and
        # count_emitted: to every method)
        options = {k: v for k, v in shared.items() if k in params.OPTION_PARAMS or k in option_names(method)}
        used |= set(options)
        options.update(own)
        radius = args.radius if method.startswith("detp") else None
        configs.append(Config(method, photons, radius=radius, **options))
    unused = sorted(set(shared) - used)
    if unused:
        raise OclgiError(f"option(s) {unused} are taken by none of the methods {[m for m, _ in methods]}")
    return configs


def _image_module():
    """oclgi.study.image, with the mitsuba package checked before any work."""
    from . import mitsuba as mitsuba_reference
    from . import image as study_image

    mitsuba_reference.load_mitsuba()
    return study_image


def run(args, comm=None) -> None:
    """The study command; ``comm``: an MPI communicator, each estimate's
    photons then split over its ranks (oclgi.distributed.EveryRank) and rank
    0 writing the outputs."""
    from .. import distributed
    from ..engine import Engine
    from ..scene.description import load_file
    from .run import run_study, seed_total
    from .stats import equal_time

    if comm is not None and args.image:
        raise OclgiError("--image does not run over MPI ranks yet: run it in one process")

    out = args.output
    if out.exists() and not out.is_dir():
        raise OclgiError(f"{out}: exists and is not a folder")
    seed_total(args.seeds)  # checked (and its list's size) before anything is built; run_study makes the list
    points = _points(args.points)
    reference = _reference(args.reference)
    image = _image_module() if args.image else None

    if comm is None:
        engine = Engine(load_file(args.scene), device=args.device, local_size=args.local_size,
                        progress=False if args.quiet else None)
    else:
        engine = distributed.EveryRank(distributed.engine(comm, args.scene, device=args.device,
                                                          local_size=args.local_size,
                                                          progress=False if args.quiet else None), comm)
    configs = _configs(engine, args)
    if image is not None:
        engine.view_camera()  # no camera: fail before the long work
    root = distributed.is_root(comm)
    result = run_study(engine, configs, points=points, seeds=args.seeds, reference=reference,
                       point_seed=args.point_seed, progress=False if args.quiet or not root else None)
    if not root:
        return
    if image is not None:  # first: its five files are written all or none, then the study's
        first = configs[0]
        summary = image.compare_with_mitsuba(engine, out, spp=args.spp, method=first.method,
                                             photons=max(first.photons), radius=first.radius, **first.options)
        print(f"wrote the image comparison to {out}")
        if not args.quiet:
            o = summary["oclgi"]
            print(f"image vs Mitsuba ({o['method']}, {o['photons']:,} photons; {summary['compared_pixels']:,} "
                  f"pixels away from edges): relative error mean {summary['rel_error_mean']:.3g}, median "
                  f"{summary['rel_error_median']:.3g}, p95 {summary['rel_error_p95']:.3g}; channel ratios "
                  f"{'/'.join(f'{r:.4f}' for r in summary['channel_mean_ratio'])} (comparison.json)",
                  file=sys.stderr)
    for path in result.write(out):
        print(f"wrote {path}")
    if not args.quiet:
        eq = equal_time(result)
        parts = ", ".join(f"{r['label']} {r['error']:.3g} ({r['ratio']:.2g}x)" for r in eq.rows)
        print(f"study: {len(result.rows)} configurations x {len(result.seeds)} seeds at {len(result.points):,} points "
              f"in {result.seconds:.1f}s; RMSE / mean reference at equal time {eq.time_s:.3g}s: {parts}",
              file=sys.stderr)
