"""The ``oclgi`` command.

    oclgi render SCENE [--method detp|impact] [--photons N] [--radius D] [-o FILE] [--no-png|--no-exr] [--force]
                       [--checkpoint FILE.npz | --resume FILE.npz [--more N]] [--progressive N]
    oclgi irradiance SCENE --points FILE.npy|.csv -o OUT.npy|.csv [--checkpoint FILE.npz | --resume ...]
    oclgi animate SCENE --path line:DX,DY,DZ|orbit:R|KEYS.csv [--frames N] -o DIR
    oclgi animate SCENE --light NAME [--light-path FILE.npy|x,y,z;x,y,z;...] [--frames N] -o DIR
    oclgi bake SCENE -o OUT.glb [--quantity irradiance|radiance] [--edge E] [--exposure X]
    oclgi study SCENE [--methods m1,m2[:key=value],...] [--photons N1,N2,...] [--seeds R]
                      [--points vertices|camera[:WxH]|random:N|FILE.npy|.csv]
                      [--reference detp[:PHOTONS]|mitsuba[:SPP]|FILE.npy] [-O key=value] [--image] -o DIR
    oclgi view SCENE [--host H] [--port P] [--allow-origin ORIGIN] [--memory SIZE] [--max-pages N] [--edge E]
                     [--all-vertices] [--photons N] [--method M] [--radius D]
    oclgi info

Errors in the input (missing or malformed files, bad numbers, no emitter, no
OpenCL device) print one line and exit with status 2, leaving no output file.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

from . import interrupt, streams
from .errors import OclgiError

streams.reopen_closed_stderr()  # before anything may write to it (2>&-: as 2>/dev/null)
# Start-up: before numpy and pyopencl are imported (they take half a second,
# and start threads), a SIGINT ignored at start is made to stay ignored in
# every thread, and a Ctrl-C during the imports ends as any other one does.
interrupt.keep_ignored()
try:
    import numpy as np

    from . import budget, params, resumable
    from .checkpoint import StopRequested
    from .params import METHODS
except KeyboardInterrupt:
    interrupt.exit_interrupted()


class _Parser(argparse.ArgumentParser):
    """argparse with oclgi's error format: one line on stderr, exit status 2."""

    def error(self, message):
        if not _other_rank():
            print(f"oclgi: error: {message} (see `{self.prog} --help`)", file=sys.stderr)
        raise SystemExit(2)


def _other_rank() -> bool:
    """One of several MPI ranks other than rank 0: every rank meets the same
    argument and input errors, and rank 0 alone says so (errors one rank
    meets alone reach rank 0 through oclgi.distributed's exchanges)."""
    from .distributed import launched_rank  # the environment only: MPI is not loaded

    return launched_rank() != 0


def _type_error(exc: OclgiError, name: str) -> argparse.ArgumentTypeError:
    """argparse's error for oclgi.params' one: argparse puts ``argument NAME:``
    before it, so a message about ``name`` itself drops its own ``NAME:``."""
    if isinstance(exc, params.ParamError) and exc.name == name:
        return argparse.ArgumentTypeError(exc.problem)
    return argparse.ArgumentTypeError(str(exc))


def _auto_or_number(text):
    return text if text.strip().lower() == params.AUTO else params.number_text(text)


def _param(reader, name, read_text=params.number_text):
    """An argparse type reading a run parameter with oclgi.params, so that the
    command line refuses what the scene file and the API refuse, in the same
    words."""
    def read(text):
        try:
            return reader(read_text(text), name)
        except OclgiError as exc:
            raise _type_error(exc, name) from None

    read.__name__ = reader.__name__  # argparse names the type in some messages
    return read


def _number_list(text):
    return [params.number_text(part) for part in text.split(",")]


def _integer(text):
    """An integer written plainly or in exponent form (``2e5``); never rounds."""
    return params.integral(params.number_text(text))


def _integer_type(ok, expected: str):
    """An argparse type reading an integer (``_integer``) for which ``ok(value)`` holds."""
    def read(text):
        value = _integer(text)
        if value is None or not ok(value):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value
    return read


_positive_int = _integer_type(lambda v: v > 0, "a positive integer")
_int_text = _integer_type(lambda v: True, "an integer")
_port = _integer_type(lambda v: 0 <= v <= 65535, "a port number from 0 to 65535")


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _option(text):
    """KEY=VALUE of -O (oclgi.params.option_text: numbers, true/false, words)."""
    try:
        return params.option_text(text)
    except OclgiError as exc:
        raise _type_error(exc, "-O") from None


def _method_list(text):
    """m1,m2:key=value:key=value,... -> [(method, {options})]."""
    out = []
    for part in text.split(","):
        name, *opts = part.strip().split(":")
        options = dict(_option(o) for o in opts)
        try:
            params.method(name, "--methods")
            from .estimators import check_options

            check_options(name, {k: v for k, v in options.items() if k not in params.OPTION_PARAMS})
        except OclgiError as exc:
            raise _type_error(exc, "--methods") from None
        out.append((name, options))
    return out


def _estimate_args(p):
    p.add_argument("scene", type=Path, help="scene file (TOML)")
    p.add_argument("--method", type=_param(params.method, "--method"), choices=METHODS,
                   help="estimator (default: the scene's, else detp_disc_index)")
    p.add_argument("--photons", type=_param(params.photons, "--photons"),
                   help="number of photon paths (default: the scene's)")
    p.add_argument("--radius", type=_param(params.radius, "--radius"),
                   help="DETP disc radius (default: the scene's, else 1%% of its diagonal): a larger disc is less "
                        "noisy and blurs shadows and edges over about its radius")
    p.add_argument("--seed", type=_param(params.seed, "--seed"), help="random seed (default: the scene's)")
    p.add_argument("--max-depth", type=_param(params.max_depth, "--max-depth"),
                   help="maximum path length in segments")
    p.add_argument("--device", help="OpenCL device, 'P:D' or a name substring (see `oclgi info`)")
    p.add_argument("--local-size", type=_positive_int, help="work-group size (results do not depend on it)")
    p.add_argument("-O", "--option", action="append", type=_option, default=[], metavar="KEY=VALUE",
                   help="an option of the method, e.g. -O q=0.6 -O order=morton (sphere cache), "
                        "-O leaf_size=8 (disc index), -O k=50 (photon map); also -O extension=E and "
                        "-O count_emitted=false; repeatable")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    ap = _Parser(prog="oclgi", description="Global illumination by density estimation on OpenCL.")
    ap.add_argument("--version", action="version", version=f"oclgi {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    ap.commands = sub.choices  # name -> the command's parser (resumable.settle reads its argument types)

    r = sub.add_parser("render", help="render the scene's camera to EXR (linear) and PNG (sRGB)")
    _estimate_args(r)
    r.add_argument("-o", "--output", type=Path,
                   help="output path, .exr or .png; the other format is written beside it with the same stem "
                        "(-o x.exr writes x.exr and x.png) unless --no-png or --no-exr (default: out/SCENE.exr)")
    r.add_argument("--no-png", action="store_true", default=None, help="write only the EXR")
    r.add_argument("--no-exr", action="store_true", default=None, help="write only the PNG")
    r.add_argument("--force", action="store_true",
                   help="replace an existing file of the name not given with -o even when oclgi did not write it")
    r.add_argument("--width", type=_param(params.image_size, "--width"),
                   help="image width (default: the scene camera's)")
    r.add_argument("--height", type=_param(params.image_size, "--height"),
                   help="image height (default: the scene camera's)")
    r.add_argument("--exposure", type=_param(params.exposure, "--exposure", _auto_or_number),
                   help="PNG exposure multiplier, or 'auto' (the image's log-average luminance to middle grey)")
    r.add_argument("--view", type=_param(params.view, "--view", str), metavar="|".join(params.VIEWS),
                   help="the PNG's view transform: srgb (the default: clamp and sRGB encoding, the same pixels as "
                        "before the option existed; highlights clip), agx (Sobotka's AgX: highlights roll off and "
                        "desaturate) or filmic (an ACES fit); the EXR stays linear radiance, and the PNG and EXR "
                        "record the view (oclgi:view)")
    r.add_argument("--layers", action="store_true", default=None,
                   help="also write the irradiance, albedo, normal and depth layers into the EXR "
                        "(irradiance.R, albedo.R, normal.X, depth.Z, ...; for compositing and denoisers)")
    r.add_argument("--spp", type=_param(params.samples_per_pixel, "--spp"),
                   help="samples per pixel, each a query point (default: 16 with the default estimate, see "
                        "--plain; 1, the pixel's centre, with --plain or -O options of the estimate); the photons "
                        "are shared, so 4 costs far less than 4 renders")
    r.add_argument("--plain", action="store_true",
                   help="the method's own estimate alone (one sample a pixel unless --spp, the photons' density). "
                        "By default a DETP method takes --spp 16 -O direct=exact -O direct_samples=4 -O "
                        "direct_mis=light -O gather=128 -O gather_spacing=3 (exact direct light at every sample, "
                        "the indirect gathered at one pixel in 3 x 3 and interpolated; fewer samples and a wider "
                        "spacing for images past 512 x 512): the fastest to a path tracer's error on the image "
                        "benchmarks (0.24-1.10x Mitsuba 3's time to its 256-spp error on three scenes, which the "
                        "plain estimate reaches on one; bench/README.md); --spp or any of those options sets them yourself")
    resumable.add_arguments(r, progressive=True)

    i = sub.add_parser("irradiance", help="irradiance at given points (sensors)")
    _estimate_args(i)
    i.add_argument("--points", type=Path, help=".npy (n, 6) or .csv: x,y,z,nx,ny,nz (required unless --resume)")
    i.add_argument("-o", "--output", type=Path, help=".npy (n, 3) or .csv output (required unless --resume)")
    i.add_argument("--units", choices=("radiometric", "photometric"),
                   help="radiometric: irradiance E_r, E_g, E_b in W/m^2 (default); photometric: illuminance in "
                        "lux, one column (RGB as linear Rec. 709, 683 lm/W)")
    i.add_argument("--plain", action="store_true",
                   help="the method's own estimate alone. By default a DETP method takes -O radius_mode=adaptive "
                        "-O direct=exact -O gather=1024 (fewer rays past 256 points): the most accurate at "
                        "equal time on the area-, sky- and sun-lit benchmarks (median 0.1-1.7%% against "
                        "1.2-4.2%% plain, no point off by 2x; bench/README.md); giving any of the three "
                        "options sets them yourself")
    resumable.add_arguments(i)

    a = sub.add_parser("animate", help="move an object along a path; incremental update and one image per frame")
    _estimate_args(a)
    a.add_argument("--object", help="the movable object to move (default: the scene's only one)")
    a.add_argument("--path", help="line:DX,DY,DZ | orbit:R[,TURNS] | keyframes .csv/.npy "
                   "(rows x,y,z[,angle about Y] or 16 numbers of a 4x4 matrix)")
    a.add_argument("--light", help="move this point or spot light (its name, or its index among the scene's point "
                   "and spot lights) instead of an object: every position's paths traced once and reused by every "
                   "frame (path reuse; --photons counts the paths per position)")
    a.add_argument("--light-path", metavar="FILE.npy|x,y,z;...",
                   help="the light's keyframes, rows x,y,z (or x,y,z,dx,dy,dz: a spot's position and axis), "
                        "interpolated over the frames (default: the light's own path in the scene file)")
    a.add_argument("--frames", type=_param(budget.frames, "--frames"), default=30, help="number of frames (default 30)")
    a.add_argument("-o", "--output", type=Path, required=True, help="folder for frame_NNNN.png and timing.csv")
    a.add_argument("--exr", action="store_true", help="also write each frame's linear EXR")
    a.add_argument("--video", type=Path, metavar="FILE.gif|.mp4",
                   help="also write the frames as one video (pip install 'oclgi[video]')")
    a.add_argument("--fps", type=_positive_float, default=24.0, help="frames per second of --video (default 24)")
    a.add_argument("--dynamic", choices=[m for m in METHODS if m.startswith("detp")],
                   help="DETP variant that recomputes the pixels on the moving object (default detp_disc_index, "
                        "summed in the pass that finds the affected paths)")
    a.add_argument("--exposure", type=_positive_float, default=1.0, help="PNG exposure multiplier")

    s = sub.add_parser("study", help="compare estimators: bias, variance, time, efficiency, bounds")
    s.add_argument("scene", type=Path, help="scene file (TOML)")
    s.add_argument("--methods", type=_method_list, default=None, metavar="M1,M2,...",
                   help="estimators, each optionally with its own options, e.g. "
                        "detp_disc_index,photon_map,photon_map:estimator=k,impact "
                        "(default: detp_disc_index,photon_map,impact)")
    s.add_argument("--photons", type=_param(params.photon_counts, "--photons", _number_list), default=None,
                   metavar="N1,N2,...",
                   help="photon counts, each run by every method (default: the scene's count /10, /3 and x1)")
    s.add_argument("--seeds", type=_int_text, default=8, metavar="R",
                   help="independent runs per configuration, at least 2 (default 8)")
    s.add_argument("--points", default="random:256",
                   help="vertices | camera[:WxH] | random:N | FILE.npy|.csv (default random:256)")
    s.add_argument("--point-seed", type=_param(params.seed, "--point-seed"), default=0,
                   help="seed of the random points (default 0)")
    s.add_argument("--reference", default="detp",
                   help="detp[:PHOTONS] (high-photon DETP, default) | mitsuba[:SPP] | FILE.npy "
                        "(exact irradiance, (n, 3) or (n,))")
    s.add_argument("--radius", type=_param(params.radius, "--radius"), help="DETP disc radius (default: the scene's)")
    s.add_argument("-O", "--option", action="append", type=_option, default=[], metavar="KEY=VALUE",
                   help="an option given to every method that takes it, e.g. -O k=50 (extension and "
                        "count_emitted: to every method); repeatable")
    s.add_argument("--image", action="store_true",
                   help="also render the first method at the largest count and compare the image with "
                        "Mitsuba's (oclgi.exr, mitsuba.exr, error.exr, error.png in DIR)")
    s.add_argument("--spp", type=_positive_int, default=256, help="Mitsuba samples per pixel for --image")
    s.add_argument("--device", help="OpenCL device, 'P:D' or a name substring (see `oclgi info`)")
    s.add_argument("--local-size", type=_positive_int, help="work-group size (results do not depend on it)")
    s.add_argument("-o", "--output", type=Path, required=True,
                   help="folder for study.md, study.csv, error_vs_time.png, variance_vs_photons.png")
    s.add_argument("--quiet", action="store_true", help="no progress bar or summary")

    b = sub.add_parser("bake", help="bake the solution into a glTF: vertex colours of the scene cut to a fine edge")
    _estimate_args(b)
    b.add_argument("-o", "--output", type=Path, required=True, help="output .glb (glTF 2.0, binary)")
    b.add_argument("--quantity", choices=("irradiance", "radiance"), default="irradiance",
                   help="irradiance (default: the light arriving, for a renderer to multiply by its own "
                        "textures) or radiance (emission + albedo x irradiance / pi, the materials' albedos)")
    b.add_argument("--edge", type=_positive_float,
                   help="longest triangle edge of the baked mesh (default: the disc radius)")
    b.add_argument("--exposure", type=_positive_float, default=1.0,
                   help="multiplier of the colours shown (COLOR_0, _COLOR_SRGB); the float values are kept as "
                        "they are in _IRRADIANCE or _RADIANCE")

    v = sub.add_parser("view", help="the scene in the browser: orbit, drag objects, watch the light follow "
                       "(a local web server; prints its URL)")
    v.add_argument("scene", type=Path, help="scene file (TOML)")
    v.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this machine only; any other address, such as "
                        "0.0.0.0, lets other machines run work on this one's device)")
    v.add_argument("--port", type=_port, default=8765, help="TCP port (default 8765; 0: any free one)")
    v.add_argument("--allow-origin", action="append", default=[], metavar="ORIGIN",
                   help="another origin whose pages may open the viewer's socket, e.g. http://192.168.1.5:8765 "
                        "(by default only the server's own page may; every request also needs the token in the "
                        "URL it prints); repeatable")
    v.add_argument("--memory", metavar="SIZE",
                   help="memory budget of all pages together, e.g. 8G (default: half of the device's memory and "
                        "of the machine's); a page's request past it gets an error, its session stays as it was")
    v.add_argument("--max-pages", type=_positive_int, default=8, metavar="N",
                   help="pages served at once (default 8)")
    v.add_argument("--edge", type=_positive_float,
                   help="longest edge of the tessellated triangles whose vertices carry the light "
                        "(default: the disc radius)")
    v.add_argument("--all-vertices", action="store_true",
                   help="query every vertex of a movable object (default: one per edge-sized cell of its mesh, "
                        "each vertex showing its cell's value: a fine mesh's vertices are most of an update)")
    v.add_argument("--method", type=_param(params.method, "--method"), choices=METHODS,
                   help="estimator of each page's session (default: the scene's, else detp_disc_index)")
    v.add_argument("--photons", type=_param(params.photons, "--photons"),
                   help="photon paths per page (default: the scene's)")
    v.add_argument("--radius", type=_param(params.radius, "--radius"),
                   help="DETP disc radius (default: the scene's, else 1%% of its diagonal)")
    v.add_argument("--device", help="OpenCL device, 'P:D' or a name substring (see `oclgi info`)")
    v.add_argument("--local-size", type=_positive_int, help="work-group size (results do not depend on it)")
    v.add_argument("--quiet", action="store_true", help="print only the URL")

    sub.add_parser("info", help="list OpenCL devices")
    w = sub.add_parser("warm", help="compile every kernel into PoCL's cache, so that later runs start at once "
                       "(the make targets' set-up runs it)")
    w.add_argument("--device", help="OpenCL device, 'P:D' or a name substring (see `oclgi info`)")
    w.add_argument("--quiet", action="store_true", help="no progress or summary")
    for command in sub.choices.values():
        command.add_argument("--verbose", action="store_true",
                             help="show the OpenCL compiler's output (as OCLGI_COMPILER_OUTPUT=1 does)")
    return ap


def _engine(args):
    from .engine import Engine
    from .scene.description import load_file

    scene = load_file(args.scene)
    return Engine(scene, device=args.device, local_size=args.local_size,
                  progress=None if not args.quiet else False)


def _est_kwargs(args):
    return dict(method=args.method, photons=args.photons, radius=args.radius, seed=args.seed,
                max_depth=args.max_depth, **dict(args.option))


def _render_outputs(args) -> list[Path]:
    """The files ``render`` writes: the one -o names and, unless --no-png or
    --no-exr, the other format beside it. A file of the name not given (both,
    by default) may replace an existing one only when oclgi wrote that one
    (or with --force): a user's photo.png survives ``-o photo.exr``."""
    from .io import check_not_input, is_oclgi_image

    named = args.output
    out = named or Path("out") / f"{args.scene.stem}.exr"
    suffix = out.suffix.lower()
    if suffix not in (".exr", ".png"):
        raise OclgiError(f"{out}: the output must end in .exr or .png")
    if args.no_png and args.no_exr:
        raise OclgiError("--no-png and --no-exr together leave nothing to write")
    for off, flag, refused in ((args.no_png, "--no-png", ".png"), (args.no_exr, "--no-exr", ".exr")):
        if off and named is not None and suffix == refused:
            raise OclgiError(f"{flag} contradicts -o {named}")
    exr = out if suffix == ".exr" else out.with_suffix(".exr")
    png = out if suffix == ".png" else out.with_suffix(".png")
    paths = [p for p, off in ((exr, args.no_exr), (png, args.no_png)) if not off]
    check_not_input(paths, {args.scene: "the scene file"})
    for p in paths:
        if p != named and p.is_file() and not args.force and not is_oclgi_image(p):
            other = "--no-png" if p.suffix == ".png" else "--no-exr"
            raise OclgiError(f"{p} exists and oclgi did not write it: give --force to replace it, "
                             f"{other} to leave it, or another -o")
    return paths


def _world(args, command: str):
    """The MPI communicator when the command runs as one of several ranks
    (``mpirun -n K oclgi ...``), else None. Under MPI, rank 0 writes."""
    from . import distributed

    comm = distributed.world()
    if comm is None:
        return None
    if command not in ("render", "irradiance", "study"):
        raise OclgiError(f"{command} does not run over MPI ranks (render, irradiance and study do): run it in "
                         "one process")
    given = [f for f in ("checkpoint", "resume", "more", "progressive") if getattr(args, f, None) is not None]
    given += ["layers"] if getattr(args, "layers", False) else []
    if given:
        raise OclgiError(f"--{given[0]} does not run over MPI ranks yet: run it in one process")
    return comm


def _mpi_engine(args, comm):
    from . import distributed

    return distributed.engine(comm, args.scene, device=args.device, local_size=args.local_size,
                              progress=None if not args.quiet else False)


def cmd_render(args):
    from .io import check_output, write_images

    paths = _render_outputs(args)
    for p in paths:
        check_output(p)
    resumable.check_arguments(args, {args.scene: "the scene file", **{p: "an image output" for p in paths}})
    comm = _world(args, "render")
    if comm is not None:
        from . import distributed

        engine = _mpi_engine(args, comm)
        _render_preset(args, engine, distributed.is_root(comm))
        result = distributed.render(engine, comm, width=args.width, height=args.height, exposure=args.exposure,
                                    spp=args.spp, view=args.view, **_est_kwargs(args))
        if not distributed.is_root(comm):
            return
        _say_preset(args)
        write_images({p: result.radiance if p.suffix.lower() == ".exr" else result.pixels for p in paths},
                     metadata=result.metadata)
        summary = f"{result.stats.summary()} | {comm.size} ranks"
    else:
        engine = _engine(args)
        _render_preset(args, engine, True)

        def write(run, est):  # all or none: a failure leaves neither file
            result = engine.render_result(run, est, args.exposure, args.layers, args.view)
            exr, channels = result.exr_channels()
            write_images({p: exr if p.suffix.lower() == ".exr" else result.pixels for p in paths},
                         metadata=result.metadata, channels={p: channels for p in paths if p.suffix.lower() == ".exr"})
            return result

        def snapshot(run, est):
            write(run, est)
            if not args.quiet:
                print(f"oclgi: {run.traced:,} photons: wrote {', '.join(map(str, paths))}", file=sys.stderr)

        def make_run(**kw):
            run = engine.render_run(width=args.width, height=args.height, spp=args.spp, **kw)
            _say_preset(args)
            return run

        run, est = resumable.execute(args, engine, make_run, snapshot)
        summary = write(run, est).stats.summary()
    if not args.quiet:
        print(summary, file=sys.stderr)
    for p in paths:
        print(f"wrote {p}")


def _preset_inputs(args, engine) -> tuple[str, dict]:
    """What a command's preset is chosen from: the run's method's family and
    the -O options given, with the run's count_emitted (the scene's unless given)."""
    from .estimators import ESTIMATORS

    given = dict(args.option)
    run = engine.run_params(args.method, args.photons, args.radius, args.seed, args.max_depth,
                            given.get("extension"), given.get("count_emitted"))
    return ESTIMATORS[run.method].family, {**given, "count_emitted": run.count_emitted}


def _render_preset(args, engine, say: bool) -> None:
    """The command's default render (oclgi/estimators/render_preset.py):
    its samples per pixel and options, unless --plain, --spp or one of its
    options is given, or the run is resumed (the checkpoint has them)."""
    from .estimators.render_preset import describe, render_settings

    if args.plain or args.resume is not None:
        return
    cam = engine.view_camera(None, args.width, args.height)
    extra = render_settings(*_preset_inputs(args, engine), "spp" in args.named_settings, cam.width, cam.height)
    if extra:
        args.spp = extra.pop("spp")
        args.settings["spp"] = args.spp
        args.option = list(args.option) + list(extra.items())
        if say and not args.quiet:
            args.preset_note = describe({"spp": args.spp, **extra})


def _say_preset(args) -> None:
    """The preset's line, once its run is made (a refused option fails first, alone)."""
    note = getattr(args, "preset_note", None)
    if note:
        print(note, file=sys.stderr)
        args.preset_note = None


def _irradiance_output(args, est):
    """The values and columns ``irradiance`` writes, in ``--units``."""
    if args.units == "photometric":
        from .photometry import illuminance_lux

        return illuminance_lux(est.irradiance), ("E_v_lux",)
    return est.irradiance, ("E_r", "E_g", "E_b")


def _sensor_preset(args, engine, n_points: int, say: bool) -> None:
    """The command's default estimate (oclgi/estimators/sensor_preset.py),
    added to the -O options unless --plain."""
    from .estimators.sensor_preset import describe, sensor_options

    if args.plain:
        return
    extra = sensor_options(*_preset_inputs(args, engine), n_points)
    if extra:
        args.option = list(args.option) + list(extra.items())
        if say and not args.quiet:
            print(describe(extra), file=sys.stderr)


def cmd_irradiance(args):
    from .io import check_not_input, check_output, write_array
    from .queries import from_file

    if args.output.suffix.lower() not in (".npy", ".csv"):
        raise OclgiError(f"{args.output}: the output must end in .npy or .csv")
    check_output(args.output)
    check_not_input([args.output], {args.scene: "the scene file", args.points: "the points file (--points)"})
    resumable.check_arguments(args, {args.scene: "the scene file", args.points: "the points file (--points)",
                                     args.output: "the output"})
    comm = _world(args, "irradiance")
    if comm is not None:
        from . import distributed

        points = distributed.on_root(comm, from_file, args.points)
        engine = _mpi_engine(args, comm)
        _sensor_preset(args, engine, len(points), distributed.is_root(comm))
        est = distributed.irradiance(engine, points, comm, **_est_kwargs(args))
        if not distributed.is_root(comm):
            return
        ranks = f" | {comm.size} ranks"
    else:
        points = from_file(args.points)
        engine = _engine(args)
        if args.resume is None:  # a resumed run takes its options from the checkpoint
            _sensor_preset(args, engine, len(points), True)
        _run, est = resumable.execute(args, engine, lambda **kw: engine.run(points, **kw))
        ranks = ""
    values, columns = _irradiance_output(args, est)
    path = write_array(args.output, values, points, columns)
    if not args.quiet:
        print(est.stats.summary() + ranks, file=sys.stderr)
    print(f"wrote {path}")


def cmd_bake(args):
    from .bake import bake, write_glb
    from .io import check_not_input, check_output

    if args.output.suffix.lower() != ".glb":
        raise OclgiError(f"{args.output}: the output must end in .glb")
    check_output(args.output)
    check_not_input([args.output], {args.scene: "the scene file"})
    _world(args, "bake")
    engine = _engine(args)
    result = bake(engine, edge=args.edge, quantity=args.quantity, exposure=args.exposure, **_est_kwargs(args))
    write_glb(result, args.output)
    vertices = sum(len(g.vertices) for g in result.geometry.values())
    faces = sum(len(g.faces) for g in result.geometry.values())
    if not args.quiet:
        print(result.metadata["stats"].summary(), file=sys.stderr)
    print(f"wrote {args.output} ({len(result.geometry)} meshes, {vertices:,} vertices, {faces:,} triangles, "
          f"{args.quantity})")


def _animation_folder(args, keyframes: str, what: str) -> tuple[Path, dict]:
    """The frames' folder, checked before any work: a folder (or none yet),
    writable, and none of its frames or timing log one of the inputs; and
    the inputs (path -> what it is)."""
    from .incremental.animate import output_names
    from .io import check_not_input, check_output

    out = args.output
    if out.exists() and not out.is_dir():
        raise OclgiError(f"{out}: exists and is not a folder")
    check_output(out / "timing.csv")
    inputs = {args.scene: "the scene file"}
    if Path(keyframes).is_file():
        inputs[Path(keyframes)] = what
    check_not_input([out / n for n in output_names(args.frames, args.exr)], inputs)
    return out, inputs


def cmd_animate(args):
    if args.light is not None or args.light_path is not None:
        return _animate_light(args)
    if args.path is None:
        raise OclgiError("animate needs --path (an object's) or --light (with --light-path, or a light with a path "
                         "in the scene file)")
    from .incremental.animate import animate, poses
    from .incremental.session import Session
    from .io import check_not_input, check_output

    out, inputs = _animation_folder(args, args.path, "the keyframes file (--path)")
    if args.video is not None:
        from . import video

        video.check(args.video)
        check_output(args.video)
        check_not_input([args.video], inputs)
    poses(args.path, args.frames)  # a bad path fails before any work
    engine = _engine(args)
    movable = [o.name for o in engine.scene.objects if o.movable]
    name = args.object
    if name is None:
        if len(movable) != 1:
            raise OclgiError(f"--object is needed: the scene has {len(movable)} movable objects {movable}")
        name = movable[0]
    engine.scene.object_id(name)
    session = Session(engine, dynamic=args.dynamic, **_est_kwargs(args))
    show = None if args.quiet or not sys.stderr.isatty() else (
        lambda f, r: print(f"\rframe {f + 1}/{args.frames}: {r['paths']:,} paths re-traced, "
                           f"{r['total_s'] * 1e3:.0f} ms", end="", file=sys.stderr))
    rows = animate(session, name, args.path, args.frames, out, args.exposure, args.exr, show)
    if show:
        print(file=sys.stderr)
    if not args.quiet:
        update = [r["total_s"] for r in rows]
        print(f"{len(rows)} frames of {name!r}: setup {session.setup_seconds:.2f}s, update median "
              f"{np.median(update) * 1e3:.1f} ms ({1 / max(np.median(update), 1e-9):.1f} updates/s), "
              f"{np.mean([r['paths'] for r in rows]):,.0f} paths re-traced per frame", file=sys.stderr)
    print(f"wrote {len(rows)} frames and timing.csv to {out}")
    if args.video is not None:
        from .incremental.animate import frame_paths
        from .io import read_image
        from .video import write_video

        frames = [np.rint(read_image(p) * 255).astype(np.uint8) for p in frame_paths(out, len(rows))]
        print(f"wrote {write_video(args.video, frames, args.fps)}")


def _animate_light(args):
    from .incremental.animate import animate_light
    from .tracing.light_reuse import LightReuse, light_path

    if args.path is not None or args.object is not None or args.dynamic is not None or args.video is not None:
        raise OclgiError("--light moves a light: --path, --object, --dynamic and --video go with objects")
    if args.light is None:
        raise OclgiError("--light-path needs --light (the light it moves)")
    out, _ = _animation_folder(args, args.light_path or "", "the light's keyframes file (--light-path)")
    if args.light_path is not None:
        positions, directions = light_path(args.light_path, args.frames)  # a bad path fails before any work
    engine = _engine(args)
    light = int(args.light) if args.light.isdigit() else args.light
    if args.light_path is None:  # the light's own path, from the scene file
        from .tracing.light_reuse import find_light

        _, found = find_light(engine.scene, light)
        if found.path is None:
            raise OclgiError(f"light {args.light!r} has no path in the scene file: give --light-path")
        positions, directions = light_path(np.array(found.path, np.float64), args.frames, f"light {args.light!r} path")
    options = dict(args.option)
    est_args = {k: options.pop(k) for k in ("extension", "count_emitted") if k in options}
    reuse = LightReuse(engine, light, positions, directions, photons=args.photons, seed=args.seed,
                       max_depth=args.max_depth)
    show = None if args.quiet or not sys.stderr.isatty() else (
        lambda f, r: print(f"\rframe {f + 1}/{args.frames}: {r['total_s'] * 1e3:.0f} ms", end="", file=sys.stderr))
    rows = animate_light(reuse, out, args.exposure, args.exr, show, method=args.method, radius=args.radius,
                         **est_args, **options)
    if show:
        print(file=sys.stderr)
    if not args.quiet:
        frame = [r["total_s"] for r in rows]
        print(f"{len(rows)} frames of light {args.light!r}: {reuse.n_paths:,} paths traced once in "
              f"{reuse.seconds['trace']:.2f}s (weights {reuse.seconds['weights']:.2f}s), frame median "
              f"{np.median(frame) * 1e3:.1f} ms", file=sys.stderr)
    print(f"wrote {len(rows)} frames and timing.csv to {out}")


def cmd_study(args):
    from .study.cli import run

    run(args, _world(args, "study"))


def cmd_warm(args):
    from .warm import warm

    show = None if args.quiet or not sys.stderr.isatty() else (
        lambda text: print(f"\roclgi warm: {text:<40}", end="", file=sys.stderr))
    done = warm(args.device, show)
    if show:
        print(file=sys.stderr)
    if not args.quiet:
        print(f"oclgi warm: {done['programs']} programs, {done['kernels']} kernels compiled into the cache "
              f"in {done['seconds']:.1f}s", file=sys.stderr)


def cmd_view(args):
    from .viewer.command import view

    view(args)


def cmd_info(_args):
    from .cl.device import describe_devices, list_devices, no_device_message

    if not list_devices():
        raise OclgiError(no_device_message())
    print(describe_devices())


def _one_line(text) -> str:
    """A message on one line (compiler logs and library errors may span several)."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"oclgi: warning: {_one_line(message)}", file=sys.stderr)


def main(argv=None) -> int:
    """The command; returns its exit status. Whatever happens after start-up,
    it ends with one line at most on stderr: an OclgiError's message, or
    ``oclgi: interrupted`` (130) on Ctrl-C, or a closed or full stdout's
    (oclgi.streams)."""
    try:
        # argv None: run as the command (the console script, python -m oclgi),
        # the process ends after this; a list: called in-process.
        with interrupt.handled(command_line=argv is None):
            return _run(argv)
    except KeyboardInterrupt:
        interrupt.say_interrupted()
        return interrupt.EXIT_STATUS


def _run(argv) -> int:
    try:
        with streams.guarded_stdout(), warnings.catch_warnings():
            parser = build_parser()
            args = parser.parse_args(argv)  # --help writes to stdout too
            if args.command in resumable.SETTINGS:  # the settings not named: a checkpoint's, else defaults
                resumable.settle(args, parser.commands[args.command])
            if args.verbose:
                from .cl.programs import COMPILER_OUTPUT_ENV

                os.environ[COMPILER_OUTPUT_ENV] = "1"
            warnings.showwarning = _show_warning
            if args.command == "animate":
                _world(args, args.command)  # refused under MPI, before any work
            {"render": cmd_render, "irradiance": cmd_irradiance, "animate": cmd_animate,
             "study": cmd_study, "view": cmd_view, "info": cmd_info, "warm": cmd_warm,
             "bake": cmd_bake}[args.command](args)
    except OclgiError as exc:
        if not _other_rank():
            print(f"oclgi: error: {_one_line(exc)}", file=sys.stderr)
        return exc.exit_code
    except StopRequested as stop:
        interrupt.ignore_further()
        print(f"oclgi: interrupted ({stop}); the run is saved in {stop.path}: continue it with "
              f"--resume {stop.path}", file=sys.stderr)
        return interrupt.EXIT_STATUS
    except streams.StdoutError as exc:  # the files were written before their "wrote" lines
        return streams.stdout_failed(exc)
    except OSError as exc:
        # A file the checks did not foresee failing (a name too long for the
        # file system, a disk gone): the environment's error, told as one;
        # outputs are staged under temporary names, so none is left partial.
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"oclgi: error: {_one_line(where + (exc.strerror or str(exc)))}", file=sys.stderr)
        return 2
    except MemoryError:
        print("oclgi: error: out of memory (the job is larger than this machine's memory; "
              "use fewer photons, points or pixels)", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
