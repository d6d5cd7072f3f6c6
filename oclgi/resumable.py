"""A command's run that survives being stopped: checkpoints, resume, more
photons and progressive images (``render`` and ``irradiance``).

    oclgi render scene.toml --photons 1e8 --checkpoint run.npz     # saved every 10 s, at the end, on Ctrl-C
    oclgi render scene.toml --resume run.npz                       # goes on where it stopped
    oclgi render scene.toml --resume run.npz --more 5e7            # 1.5e8 photons, as one run of 1.5e8

Resumed and extended runs equal one uninterrupted run bit for bit (the sums
are integers of path ranges, oclgi/tracing/run.py). A resumed run takes the
checkpoint's parameters where the command line gives none; one the command
line gives must agree with it, as must the scene and the query points
(oclgi/checkpoint.py), or the command stops with exit status 2 before any
work. The command line's own settings (``SETTINGS``: image size, samples,
outputs, ...) are kept in the checkpoint too, so that ``--resume FILE``
alone goes on as the run was started; one the command line names replaces
the saved one (the query points must still agree).
"""

from __future__ import annotations

import math
from pathlib import Path

from . import checkpoint, params
from .errors import OclgiError

# args attribute -> RunParams key, for the parameters the command line may give
RUN_ARGS = {"method": "method", "photons": "photons", "radius": "radius", "seed": "seed", "max_depth": "max_depth"}

# Per command, the command line's own settings a checkpoint keeps, with their
# defaults (argparse's are None, so that a setting not named is told from one
# named at its default value).
_LONG_RUNS = {"batch_paths": None, "checkpoint_every": checkpoint.DEFAULT_EVERY}
SETTINGS = {
    "render": {"width": None, "height": None, "spp": 1, "exposure": 1.0, "view": "srgb", "layers": False,
               "output": None, "no_png": False, "no_exr": False, "progressive": None, **_LONG_RUNS},
    "irradiance": {"points": None, "output": None, "units": "radiometric", **_LONG_RUNS},
}
REQUIRED = {"irradiance": ("points", "output")}


def _seconds(text):
    import argparse

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a number of seconds >= 0, got {text!r}")
    return value


def add_arguments(p, progressive: bool = False) -> None:
    g = p.add_argument_group("long runs")
    g.add_argument("--checkpoint", type=Path, metavar="FILE.npz",
                   help="save the run's state to FILE every --checkpoint-every seconds, at the end and on "
                        "Ctrl-C or SIGTERM (then exit 130); continue it with --resume FILE")
    g.add_argument("--resume", type=Path, metavar="FILE.npz",
                   help="continue the run saved in FILE (and keep saving to it, unless --checkpoint names "
                        "another file); parameters not given are the saved run's")
    g.add_argument("--more", type=lambda t: params.photons(params.number_text(t), "--more"), metavar="N",
                   help="with --resume: add N photons to the saved run (equal to one run of the sum)")
    g.add_argument("--checkpoint-every", type=_seconds, metavar="SECONDS",
                   help=f"seconds of work between saves (default {checkpoint.DEFAULT_EVERY:g})")
    g.add_argument("--batch-paths", type=lambda t: params.photons(params.number_text(t), "--batch-paths"),
                   metavar="N", help="photon paths per batch (default: as 256 MiB of segments hold; results "
                                     "do not depend on it, saves and progress come between batches)")
    if progressive:
        g.add_argument("--progressive", type=lambda t: params.photons(params.number_text(t), "--progressive"),
                       metavar="N", help="write the image every N photons as the run goes (and at its end)")


def check_arguments(args, inputs: dict) -> None:
    """Argument combinations, before any work."""
    from .io import check_not_input, check_output

    if args.more is not None and args.resume is None:
        raise OclgiError("--more adds photons to a saved run: give --resume FILE too")
    target = save_path(args)
    if target is None:
        return
    if target.suffix.lower() != checkpoint.SUFFIX:
        raise OclgiError(f"{target}: a checkpoint file must end in {checkpoint.SUFFIX}")
    if args.resume is None and target.exists():
        raise OclgiError(f"{target} exists: continue its run with --resume {target}, or remove it")
    if args.resume is not None and not args.resume.is_file():
        raise OclgiError(f"{args.resume}: no such checkpoint file")
    check_output(target)
    check_not_input([target], inputs)


def settle(args, parser) -> None:
    """The command's settings (``SETTINGS``): those the command line names,
    else with ``--resume`` the checkpoint's, else the defaults. ``parser``:
    the command's own, whose argument types check the saved values as they
    check typed ones."""
    defaults = SETTINGS[args.command]
    saved = {}
    if args.resume is not None:
        saved = checkpoint.read_record(args.resume).get("command") or {}
        if not isinstance(saved, dict):
            raise OclgiError(f"{args.resume}: a damaged oclgi checkpoint (its command settings)")
    actions = {a.dest: a for a in parser._actions}
    args.named_settings = {name for name in defaults if getattr(args, name) is not None or name in saved}
    for name, default in defaults.items():
        if getattr(args, name) is not None:
            continue
        value = saved.get(name)
        if value is not None:
            value = _saved_value(args.resume, actions[name], value)
        setattr(args, name, default if value is None else value)
    for name in REQUIRED.get(args.command, ()):
        if getattr(args, name) is None:
            flag = actions[name].option_strings[-1]
            raise OclgiError(f"{flag} is required (or --resume FILE of a run that had it)")
    args.settings = {name: checkpoint._jsonable(getattr(args, name)) for name in defaults}


def _saved_value(path, action, value):
    """A saved setting read through its argument's type, as if typed."""
    import argparse

    flag = action.option_strings[-1]
    if action.nargs == 0:  # a flag (store_true)
        if not isinstance(value, bool):
            raise OclgiError(f"{path}: a damaged oclgi checkpoint (its {flag} is {value!r})")
        return value
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise OclgiError(f"{path}: a damaged oclgi checkpoint (its {flag} is {value!r})")
    try:
        value = action.type(str(value)) if action.type is not None else str(value)
    except (argparse.ArgumentTypeError, ValueError, OclgiError) as exc:
        raise OclgiError(f"{path}: its saved {flag} {value!r} is refused: {exc}") from None
    if action.choices is not None and value not in action.choices:
        raise OclgiError(f"{path}: its saved {flag} {value!r} is not one of {', '.join(action.choices)}")
    return value


def save_path(args) -> Path | None:
    return args.checkpoint or args.resume


def run_kwargs(args, saved: dict | None) -> dict:
    """The run's parameters and options: the command line's, and for a
    resumed run the saved ones where the command line gives none."""
    given = {key: getattr(args, attr) for attr, key in RUN_ARGS.items() if getattr(args, attr) is not None}
    options = dict(args.option)
    if saved is not None:
        for key, value in (saved.get("params") or {}).items():
            if key in params.RUN_KEYS and key not in given and key not in options:
                given[key] = value
        # the saved options, those the command line names replacing theirs
        # (checked against the saved ones after: a changed option is refused)
        options = {**dict(saved.get("options") or {}), **options}
    return {**given, **options}


def execute(args, engine, make_run, snapshot=None):
    """Make the run (``make_run(**kwargs)``), resume it from ``--resume``
    and extend it by ``--more``, complete it with saves to the checkpoint
    file, and return (run, estimate). ``snapshot(run, estimate)`` is called
    every ``--progressive`` photons with the estimate so far."""
    target = save_path(args)
    if target is None:
        return _execute(args, engine, make_run, snapshot)
    with checkpoint.exclusive(target, fresh=args.resume is None):  # one run a checkpoint file at a time
        return _execute(args, engine, make_run, snapshot)


def _execute(args, engine, make_run, snapshot):
    saved, state = checkpoint.load(args.resume) if args.resume is not None else (None, None)
    kwargs = run_kwargs(args, saved)
    options = {k: v for k, v in kwargs.items() if k not in params.RUN_KEYS}
    run = make_run(**kwargs)
    if args.batch_paths is not None:
        run.set_batch(args.batch_paths)
    if saved is not None:
        checkpoint.check(args.resume, saved, checkpoint.record(run, options))
        run.restore(state)
        if args.more is not None:
            run.extend(args.more)
    target = save_path(args)
    saver = (checkpoint.Saver(target, options, args.checkpoint_every, getattr(args, "settings", None))
             if target is not None else None)
    every = getattr(args, "progressive", None)
    run.marks = every  # batches end on its multiples

    def on_batch(r, stop):
        if saver is not None:
            saver.on_batch(r)
        if every is not None and r.traced % every == 0 and not r.done:
            snapshot(r, r.finish(r.traced))
        if stop is not None and stop.signum is not None:
            if saver is not None:
                saver.save(r)
            raise checkpoint.StopRequested(stop.signum, saver.path if saver is not None else None)

    progress = None if not args.quiet else False
    if saver is None:
        est = run.complete(progress, (lambda r: on_batch(r, None)) if every is not None else None)
    else:
        with checkpoint.deferred_stop() as stop:
            est = run.complete(progress, lambda r: on_batch(r, stop))
        saver.save(run)  # the finished state: --more extends it
    return run, est
