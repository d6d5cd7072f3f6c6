"""Start-up: a cold first ``oclgi render`` against a warm one.

A cold run finds PoCL's and pyopencl's caches empty (``XDG_CACHE_HOME`` a
fresh folder): it compiles every program it uses from source and every kernel at
its first launch. A warm run finds them compiled. Three cases per workload:

- ``cold``: an empty cache, as on a fresh machine before any set-up;
- ``after warm``: a fresh cache filled by ``oclgi warm`` (what ``make
  render``'s set-up does once per machine), then the render;
- ``warm``: the same render again on a filled cache.

Workloads: the default scene as ``make render`` runs it (the Cornell box,
256 x 256, 10^6 photons, disc indexing) and a 20,000-photon render of it.
Each case runs ``--rounds`` times in alternation (the machine is shared:
alternating spreads a slow minute over every case); the table gives the
median wall time of the whole process and cold minus warm.

``--tree DIR`` times another checkout of oclgi (its package and kernels)
with this machine's venv, for before/after comparisons.

Writes ``bench/results/startup.json`` and ``startup.md`` (``-o`` another
folder). Usage: ``.venv/bin/python bench/startup.py [--rounds 5] [--tree DIR]``.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from common import RESULTS, ROOT, arguments, device, timed

WORKLOADS = {"default scene": [], "20,000 photons": ["--photons", "20000"]}


def _env(tree: Path | None, cache: Path) -> dict:
    # A fresh machine: PoCL's and pyopencl's caches both live under
    # XDG_CACHE_HOME, empty for a cold run.
    env = dict(os.environ, XDG_CACHE_HOME=str(cache))
    for name in ("POCL_CACHE_DIR", "PYOPENCL_NO_CACHE", "OCLGI_COMPILER_OUTPUT"):
        env.pop(name, None)
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
        env["OCLGI_KERNEL_DIR"] = str(tree / "kernels")
    return env


def _oclgi(env, *args) -> float:
    # from a neutral folder: `python -m` puts the working folder first on the path
    t, res = timed(subprocess.run, [sys.executable, "-m", "oclgi", *args], env=env, capture_output=True, text=True,
                   cwd=tempfile.gettempdir())
    if res.returncode != 0:
        raise SystemExit(f"oclgi {' '.join(args)} failed:\n{res.stderr}")
    return t


def measure(tree: Path | None, rounds: int, has_warm: bool) -> dict:
    scene = str((tree or ROOT) / "scenes" / "cornell_box.toml")
    out = {w: {"cold": [], "after warm": [], "warm": [], "warm-up": []} for w in WORKLOADS}
    with tempfile.TemporaryDirectory(prefix="oclgi-startup-") as tmp:
        tmp = Path(tmp)
        for r in range(rounds):
            for name, extra in WORKLOADS.items():
                args = ["render", scene, *extra, "--quiet", "-o", str(tmp / "img.exr")]
                cold = tmp / f"cold{r}"
                out[name]["cold"].append(_oclgi(_env(tree, cold), *args))
                out[name]["warm"].append(_oclgi(_env(tree, cold), *args))
                shutil.rmtree(cold)
                if has_warm:
                    filled = tmp / f"filled{r}"
                    out[name]["warm-up"].append(_oclgi(_env(tree, filled), "warm", "--quiet"))
                    out[name]["after warm"].append(_oclgi(_env(tree, filled), *args))
                    shutil.rmtree(filled)
                print(f"round {r + 1}/{rounds} {name}: " + ", ".join(
                    f"{k} {v[-1]:.2f}s" for k, v in out[name].items() if v), file=sys.stderr)
    return out


def markdown(results: dict, meta: dict) -> str:
    lines = [f"# Start-up: cold and warm `oclgi render` ({meta['label']})", "",
             f"Machine: {meta['cpu']}, {meta['cores']} cores; OpenCL device {meta['device']}; "
             f"{meta['rounds']} rounds, median wall time of the whole process.", "",
             "| workload | cold | warm | cold - warm | `oclgi warm` | after warm | after warm - warm |",
             "|---|---|---|---|---|---|---|"]
    def s(v):
        return "-" if v != v else f"{v:.2f} s"  # NaN: a case the timed code has no command for

    for name, cases in results.items():
        med = {k: statistics.median(v) if v else float("nan") for k, v in cases.items()}
        lines.append(f"| {name} | {s(med['cold'])} | {s(med['warm'])} | **{s(med['cold'] - med['warm'])}** "
                     f"| {s(med['warm-up'])} | {s(med['after warm'])} | **{s(med['after warm'] - med['warm'])}** |")
    return "\n".join(lines) + "\n"


def main():
    args = arguments(__doc__, rounds=5, output=dict(short="-o", type=Path, default=RESULTS),
                     tree=dict(type=Path, help="another checkout of oclgi to time (default: this one)"),
                     label=dict(help="what is timed, for the report (default: the tree's commit)"))
    tree = args.tree.resolve() if args.tree else None
    src = tree or ROOT
    commit = subprocess.run(["git", "-C", str(src), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    has_warm = (src / "oclgi" / "warm.py").exists()
    results = measure(tree, args.rounds, has_warm)
    dev = device()
    meta = {"label": args.label or f"commit {commit}", "commit": commit, "rounds": args.rounds,
            "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "device": f"{dev.name.strip()} ({dev.max_compute_units} units, {dev.platform.version.split(' ')[2]})",
            "loadavg": os.getloadavg()}
    try:
        with open("/proc/cpuinfo") as f:
            meta["cpu"] = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    args.output.mkdir(parents=True, exist_ok=True)
    stem = "startup" if tree is None else f"startup_{commit}"
    (args.output / f"{stem}.json").write_text(json.dumps({"meta": meta, "seconds": results}, indent=1))
    (args.output / f"{stem}.md").write_text(md := markdown(results, meta))
    print(md)


if __name__ == "__main__":
    main()
