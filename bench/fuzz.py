"""The long fuzzing campaign: thousands of generated cases, a summary table,
a reproducer folder per failure.

    python bench/fuzz.py                        # 2,000 cases, seed 0, in out/fuzz/
    python bench/fuzz.py --cases 10000 --seed 7 --formats toml,obj
    python bench/fuzz.py --subprocess           # one `python -m oclgi` per case (slow, like a user)
    python bench/fuzz.py --replay out/fuzz/reproducers/traceback/toml-0012

The cases are those of tests/test_fuzz.py (tests/fuzz/strategies.py), drawn
by hypothesis from the given seed without shrinking, so a seed names one
campaign on every machine. Each failure's input files and command line are
saved under OUT/reproducers/KIND/FORMAT-NNNN/ (the command in
``_fuzz/command.txt``), at most five per cause; OUT/summary.md holds the
tables printed at the end and OUT/failures.json every failure.
"""

from __future__ import annotations

import argparse
import json
import pickle
import shutil
import sys
import time
import traceback
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))  # the fuzz package (before bench/, where this file is)

from fuzz.oracle import KINDS, Case, Runner  # noqa: E402
from fuzz.strategies import FORMATS  # noqa: E402
from hypothesis import HealthCheck, Phase, given, seed, settings  # noqa: E402

# Share of the cases per format: parse-level formats are cheap and have the most to break.
WEIGHTS = {"toml": 3, "dict": 3, "obj": 2, "mtl": 1, "ply": 2, "gltf": 2, "points": 2, "cli": 3}
KEEP_PER_CAUSE = 5


class Campaign:
    def __init__(self, out: Path, runner: Runner):
        self.out, self.runner = out, runner
        self.rows = defaultdict(Counter)  # format -> counts
        self.seconds = Counter()
        self.causes = defaultdict(list)  # signature -> [(format, reproducer or None, detail)]
        self.failures = []
        self.broken = []  # formats whose generator failed
        self.done = 0
        self.t0 = time.perf_counter()

    def record(self, outcome) -> None:
        fmt = outcome.case.fmt
        row = self.rows[fmt]
        row["cases"] += 1
        self.seconds[fmt] += outcome.seconds
        self.done += 1
        if outcome.ok:
            row[f"exit {outcome.rc}"] += 1
        else:
            f = outcome.failure
            row[f.kind] += 1
            kept = self.causes[f.signature]
            saved = None
            if len(kept) < KEEP_PER_CAUSE:
                saved = str(outcome.case.save(self.out / "reproducers" / f.kind.replace(" ", "-")
                                              / f"{fmt}-{self.done:04d}", outcome))
            kept.append((fmt, saved, f.detail))
            self.failures.append({"format": fmt, "kind": f.kind, "signature": f.signature,
                                  "command": outcome.case.command(), "reproducer": saved, "detail": f.detail[-2000:]})
        if self.done % 50 == 0:
            print(f"  {self.done} cases, {len(self.failures)} failures, {time.perf_counter() - self.t0:.0f}s",
                  file=sys.stderr)

    def run(self, fmt: str, n: int, seed_value: int) -> None:
        @settings(max_examples=n, database=None, deadline=None, phases=[Phase.generate],
                  suppress_health_check=list(HealthCheck))
        @seed(seed_value)
        @given(FORMATS[fmt])
        def one(case):
            self.record(self.runner.run(case))

        one()

    def tables(self, header: str) -> str:
        cols = ["cases", "exit 0", "exit 2", *KINDS]
        total = sum(self.rows.values(), Counter())
        lines = [header, "", "| format | " + " | ".join(cols) + " | seconds |", "|---|" + "---:|" * (len(cols) + 1),
                 *(f"| {fmt} | " + " | ".join(str(row[c]) for c in cols) + f" | {self.seconds[fmt]:.0f} |"
                   for fmt, row in self.rows.items()),
                 "| **all** | " + " | ".join(str(total[c]) for c in cols) + f" | {sum(self.seconds.values()):.0f} |"]
        if self.broken:
            lines += ["", f"The generator of {', '.join(self.broken)} failed: those rows are short."]
        lines += ["", f"{len(self.causes)} distinct causes of failure:", "",
                  "| kind and cause | cases | formats | a reproducer |", "|---|---:|---|---|"]
        for sig, hits in sorted(self.causes.items(), key=lambda kv: -len(kv[1])):
            formats = ",".join(sorted({h[0] for h in hits}))
            repro = next((h[1] for h in hits if h[1]), "")
            rel = Path(repro).relative_to(self.out) if repro else ""
            lines.append(f"| `{sig.replace('|', '/')}` | {len(hits)} | {formats} | {rel} |")
        return "\n".join(lines) + "\n"


def _shares(total: int, formats: list) -> dict:
    weight = sum(WEIGHTS[f] for f in formats)
    shares = {f: max(1, total * WEIGHTS[f] // weight) for f in formats}
    shares[formats[0]] += max(0, total - sum(shares.values()))
    return shares


def replay(folder: Path, subprocess: bool) -> int:
    """Run a saved reproducer again (in a copy of its folder) and print what
    it did; given a folder of reproducers (out/fuzz/reproducers), every one."""
    if not (folder / "_fuzz").is_dir():
        cases = sorted(p.parent for p in folder.rglob("_fuzz") if p.is_dir())
        if not cases:
            print(f"no reproducers under {folder}")
            return 1
        failed = 0
        for case in cases:
            print(f"{case.relative_to(folder)}: ", end="")
            failed += replay(case, subprocess)
        print(f"{len(cases) - failed} of {len(cases)} pass")
        return 1 if failed else 0
    meta = folder / "_fuzz"
    argv = json.loads((meta / "argv.json").read_text())
    desc = pickle.loads((meta / "desc.pickle").read_bytes()) if argv is None else None
    files = {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*")
             if p.is_file() and "_fuzz" not in p.relative_to(folder).parts}
    case = Case(folder.name.split("-")[0], files, argv, desc)
    runner = Runner(Path("/tmp") / f"oclgi-fuzz-replay-{time.time_ns()}", subprocess=subprocess)
    try:
        outcome = runner.run(case)
    finally:
        runner.close()
        shutil.rmtree(runner.root, ignore_errors=True)
    print(outcome.describe())
    print("passes" if outcome.ok else "FAILS")
    return 0 if outcome.ok else 1


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=2000, help="cases in all, shared among the formats (default 2000)")
    ap.add_argument("--seed", type=int, default=0, help="hypothesis seed (default 0)")
    ap.add_argument("--formats", default=",".join(FORMATS), help=f"comma-separated, of {','.join(FORMATS)}")
    ap.add_argument("--subprocess", action="store_true", help="one `python -m oclgi` process per case")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds before a case counts as a hang")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "out" / "fuzz", help="results folder (default out/fuzz)")
    ap.add_argument("--replay", type=Path, help="run one saved reproducer folder again")
    args = ap.parse_args(argv)
    if args.replay:
        return replay(args.replay, args.subprocess)
    formats = [f.strip() for f in args.formats.split(",") if f.strip()]
    unknown = set(formats) - set(FORMATS)
    if unknown:
        ap.error(f"unknown formats {sorted(unknown)}")
    args.out = args.out.resolve()  # the worker changes into each case's folder
    if args.out.exists():
        shutil.rmtree(args.out)
    args.out.mkdir(parents=True)
    runner = Runner(args.out / "cases", subprocess=args.subprocess, timeout=args.timeout)
    campaign = Campaign(args.out, runner)
    shares = _shares(args.cases, formats)
    t0 = time.perf_counter()
    try:
        for fmt in formats:
            print(f"{fmt}: {shares[fmt]} cases", file=sys.stderr)
            try:
                # one seed per format, whichever others run with it
                campaign.run(fmt, shares[fmt], args.seed * 100 + list(FORMATS).index(fmt))
            except Exception:  # a generator's bug: the other formats still run
                traceback.print_exc()
                campaign.broken.append(fmt)
            (args.out / "summary.md").write_text(campaign.tables(f"Fuzzing campaign so far: seed {args.seed}"))
    finally:
        runner.close()
        shutil.rmtree(args.out / "cases", ignore_errors=True)
    wall = time.perf_counter() - t0
    header = (f"Fuzzing campaign: seed {args.seed}, {campaign.done} cases in {wall:.0f}s "
              f"({'subprocess' if args.subprocess else 'worker'} mode)")
    text = campaign.tables(header)
    (args.out / "summary.md").write_text(text)
    (args.out / "failures.json").write_text(json.dumps(campaign.failures, indent=1))
    print(text)
    return 1 if campaign.failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
