"""The ``oclgi`` command.

    oclgi render SCENE [--method detp|impact] [--photons N] [--radius D] [-o FILE]
    oclgi irradiance SCENE --points FILE.npy|.csv -o OUT.npy|.csv
    oclgi info

Errors in the input (missing or malformed files, bad numbers, no emitter, no
OpenCL device) print one line and exit with status 2, leaving no output file.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from .errors import OclgiError


def _positive_int(text):
    try:
        value = int(float(text)) if "e" in text.lower() else int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _nonneg_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return value


def _estimate_args(p):
    p.add_argument("scene", type=Path, help="scene file (TOML)")
    p.add_argument("--method", choices=["detp", "impact"], help="estimator (default: the scene's, else detp)")
    p.add_argument("--photons", type=_positive_int, help="number of photon paths (default: the scene's)")
    p.add_argument("--radius", type=_positive_float, help="DETP disc radius (default: the scene's)")
    p.add_argument("--seed", type=_nonneg_int, help="random seed (default: the scene's)")
    p.add_argument("--max-depth", type=_positive_int, help="maximum path length in segments")
    p.add_argument("--device", help="OpenCL device, 'P:D' or a name substring (see `oclgi info`)")
    p.add_argument("--local-size", type=_positive_int, help="work-group size (results do not depend on it)")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="oclgi", description="Global illumination by density estimation on OpenCL.")
    sub = ap.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render the scene's camera to EXR (linear) and PNG (sRGB)")
    _estimate_args(r)
    r.add_argument("-o", "--output", type=Path, help="output path; .exr and .png are written with its stem "
                   "(default: out/SCENE.exr)")
    r.add_argument("--width", type=_positive_int, help="image width (default: the scene camera's)")
    r.add_argument("--height", type=_positive_int, help="image height (default: the scene camera's)")
    r.add_argument("--exposure", type=_positive_float, default=1.0, help="PNG exposure multiplier")

    i = sub.add_parser("irradiance", help="irradiance at given points (sensors)")
    _estimate_args(i)
    i.add_argument("--points", type=Path, required=True, help=".npy (n, 6) or .csv: x,y,z,nx,ny,nz")
    i.add_argument("-o", "--output", type=Path, required=True, help=".npy (n, 3) or .csv output")

    sub.add_parser("info", help="list OpenCL devices")
    return ap


def _engine(args):
    from .engine import Engine
    from .scene.description import load_file

    scene = load_file(args.scene)
    return Engine(scene, device=args.device, local_size=args.local_size, progress=None if not args.quiet else False)


def _est_kwargs(args):
    return dict(method=args.method, photons=args.photons, radius=args.radius, seed=args.seed,
                max_depth=args.max_depth)


def cmd_render(args):
    from . import save_render

    out = args.output or Path("out") / f"{args.scene.stem}.exr"
    if out.suffix.lower() not in (".exr", ".png"):
        raise OclgiError(f"{out}: the output must end in .exr or .png")
    engine = _engine(args)
    result = engine.render(width=args.width, height=args.height, exposure=args.exposure, **_est_kwargs(args))
    exr, png = save_render(result, out)
    if not args.quiet:
        print(result.stats.summary(), file=sys.stderr)
    print(f"wrote {exr}")
    print(f"wrote {png}")


def cmd_irradiance(args):
    from .io import write_array
    from .queries import from_file

    if args.output.suffix.lower() not in (".npy", ".csv"):
        raise OclgiError(f"{args.output}: the output must end in .npy or .csv")
    points = from_file(args.points)
    engine = _engine(args)
    est = engine.irradiance(points, **_est_kwargs(args))
    path = write_array(args.output, est.irradiance, points)
    if not args.quiet:
        print(est.stats.summary(), file=sys.stderr)
    print(f"wrote {path}")


def cmd_info(_args):
    from .cl.device import describe_devices

    print(describe_devices())


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"oclgi: warning: {message}", file=sys.stderr)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    warnings.showwarning = _show_warning
    try:
        {"render": cmd_render, "irradiance": cmd_irradiance, "info": cmd_info}[args.command](args)
    except OclgiError as exc:
        print(f"oclgi: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("oclgi: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
