"""Running a fuzz case and judging what it did.

A case is the files of a folder and a command line (or a scene dict for
``oclgi.load_dict``). It passes when it

* exits 0 and every file it says it wrote (``wrote PATH`` on stdout, or the
  frames and ``timing.csv`` of ``animate``) exists, is not empty and reads
  back (images with OpenImageIO, arrays with numpy), and no temporary file
  is left beside them; or
* exits 2 with exactly one ``oclgi: error:`` line as the last line of stderr
  (``oclgi: warning:`` lines may come before it) and leaves no new file in
  the case folder.

Anything else is a :class:`Failure` of one kind (``KINDS``). Cases run in a
:class:`Worker` (in-process calls in a child process: fast, and a crash only
costs a restart) or, with ``Runner(subprocess=True)``, one ``python -m oclgi``
per case, the way a user runs it.
"""

from __future__ import annotations

import base64
import json
import os
import pickle
import re
import select
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

KINDS = ("traceback", "crash", "hang", "partial file", "stray temporary", "multi-line error",
         "missing output", "bad exit status")
WORKER = Path(__file__).with_name("worker.py")
# Seconds a case may take: a parse error is instant, a device run of 2,000
# photons under a second; a shared, loaded machine gets a wide margin.
TIMEOUT = 120.0


@dataclass
class Case:
    fmt: str  # the format it fuzzes: toml, dict, obj, ...
    files: dict  # relative path -> bytes
    argv: list | None = None  # the command line (None: ``desc`` goes to load_dict)
    desc: object = None

    def write(self, folder: Path) -> None:
        for name, data in self.files.items():
            p = folder / name
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(data)

    def __repr__(self):
        files = ", ".join(f"{name} ({len(data)} bytes)" for name, data in self.files.items())
        what = self.argv if self.argv is not None else f"load_dict({self.desc!r:.300})"
        return f"Case({self.fmt}: {what}; files {files})"

    def save(self, folder: Path, outcome: "Outcome | None" = None) -> Path:
        """A reproducer: the case's files, its command line (argv.json, and
        desc.pickle / desc.txt for a load_dict case) and what it did."""
        folder = Path(folder)
        if folder.exists():
            shutil.rmtree(folder)
        folder.mkdir(parents=True)
        self.write(folder)
        meta = folder / "_fuzz"
        meta.mkdir()
        (meta / "argv.json").write_text(json.dumps(self.argv))
        (meta / "command.txt").write_text(self.command() + "\n")
        if self.argv is None:
            (meta / "desc.pickle").write_bytes(pickle.dumps(self.desc))
            (meta / "desc.txt").write_text(repr(self.desc) + "\n")
        if outcome is not None:
            (meta / "outcome.txt").write_text(outcome.describe() + "\n")
        return folder

    def command(self) -> str:
        if self.argv is None:
            return "oclgi.load_dict(desc, base_dir=FOLDER)"
        import shlex

        return "oclgi " + " ".join(shlex.quote(a) for a in self.argv)


@dataclass
class Failure:
    kind: str
    detail: str  # what went wrong, in a line or a traceback
    signature: str  # groups failures of one cause

    def __str__(self):
        return f"{self.kind}: {self.detail}"


@dataclass
class Outcome:
    case: Case
    rc: int | None
    stdout: str = ""
    stderr: str = ""
    failure: Failure | None = None
    seconds: float = 0.0
    outputs: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.failure is None

    def describe(self) -> str:
        parts = [f"format {self.case.fmt}: {self.case.command()}", f"exit {self.rc}"]
        if self.failure:
            parts.append(str(self.failure))
        if self.stderr:
            parts.append("stderr:\n" + self.stderr[-3000:])
        return "\n".join(parts)


# -- running ---------------------------------------------------------------------


class Worker:
    """A child process running cases in-process (tests/fuzz/worker.py)."""

    def __init__(self, env=None):
        self.env = env
        self.proc = None

    def _start(self):
        self.proc = subprocess.Popen([sys.executable, str(WORKER)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, env=self.env, cwd=os.getcwd())
        self._buf = b""
        line = self._line(TIMEOUT)
        if line != "ready":
            raise RuntimeError(f"the fuzz worker did not start: {line!r}")

    def _line(self, timeout):
        """The next line the worker answers, or None on a timeout or its death."""
        end = time.monotonic() + timeout
        while b"\n" not in self._buf:
            left = end - time.monotonic()
            if left <= 0:
                return None
            ready, _, _ = select.select([self.proc.stdout], [], [], left)
            if ready:
                chunk = os.read(self.proc.stdout.fileno(), 1 << 20)
                if not chunk:
                    return None
                self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return line.decode()

    def run(self, request: dict, timeout: float) -> dict:
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        try:
            self.proc.stdin.write((json.dumps(request) + "\n").encode())
            self.proc.stdin.flush()
        except BrokenPipeError:
            pass
        line = self._line(timeout)
        if line is not None:
            return json.loads(line)
        if self.proc.poll() is None:  # alive and silent: a hang
            self.close()
            return {"hang": True}
        rc = self.proc.wait()
        self.proc = None
        return {"died": rc}

    def close(self):
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.kill()
            self.proc.wait()
            self.proc = None


# load_dict in a fresh process: the worker's own call, on the pickled description
_DICT_SCRIPT = """import base64, os, sys
sys.path.insert(0, sys.argv[1])
from worker import _call
sys.exit(_call({"dir": os.getcwd(), "desc": base64.b64encode(open(sys.argv[2], "rb").read())}))
"""


class Runner:
    """Runs cases in fresh folders under ``root`` and judges them."""

    def __init__(self, root: Path, subprocess: bool = False, timeout: float = TIMEOUT, keep: bool = False):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.subprocess, self.timeout, self.keep = subprocess, timeout, keep
        self.worker = None if subprocess else Worker()
        self.count = 0

    def close(self):
        if self.worker is not None:
            self.worker.close()

    def run(self, case: Case) -> Outcome:
        self.count += 1
        folder = self.root / f"case{self.count:06d}"
        if folder.exists():
            shutil.rmtree(folder)
        folder.mkdir()
        case.write(folder)
        before = _files(folder)
        t0 = time.perf_counter()
        raw = self._run_sub(case, folder) if self.subprocess else self._run_worker(case, folder)
        seconds = time.perf_counter() - t0
        outcome = judge(case, raw, folder, before)
        outcome.seconds = seconds
        if not self.keep:
            shutil.rmtree(folder, ignore_errors=True)
        return outcome

    def _run_worker(self, case, folder):
        request = {"dir": str(folder)}
        if case.argv is not None:
            request["argv"] = case.argv
        else:
            request["desc"] = base64.b64encode(pickle.dumps(case.desc)).decode()
        return self.worker.run(request, self.timeout)

    def _run_sub(self, case, folder):
        if case.argv is not None:
            cmd = [sys.executable, "-m", "oclgi", *case.argv]
        else:
            (folder / ".desc.pickle").write_bytes(pickle.dumps(case.desc))
            cmd = [sys.executable, "-c", _DICT_SCRIPT, str(WORKER.parent), ".desc.pickle"]
        try:
            res = subprocess.run(cmd, cwd=folder, capture_output=True, timeout=self.timeout)
        except subprocess.TimeoutExpired:
            return {"hang": True}
        (folder / ".desc.pickle").unlink(missing_ok=True)
        err = res.stderr.decode("utf-8", "replace")
        if res.returncode < 0:
            return {"died": res.returncode, "stderr": err}
        tb = err if "Traceback (most recent call last)" in err else None
        return {"rc": res.returncode, "stdout": res.stdout.decode("utf-8", "replace"), "stderr": err,
                "traceback": tb}


# -- judging ---------------------------------------------------------------------


def _files(folder: Path) -> set:
    return {p.relative_to(folder) for p in folder.rglob("*") if p.is_file() or p.is_symlink()}


def _where(tb: str) -> str:
    """The innermost oclgi frame of a traceback (``file.py:LINE in func``), else the last frame."""
    frames = re.findall(r'File "([^"]+)", line (\d+), in (\S+)', tb)
    ours = [f for f in frames if "/oclgi/" in f[0]] or frames
    if not ours:
        return "?"
    path, line, func = ours[-1]
    short = path.split("/oclgi/", 1)[-1] if "/oclgi/" in path else os.path.basename(path)
    return f"{short}:{line} in {func}"


def _last_line(tb: str) -> str:
    lines = [line for line in tb.strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else ""


def _generic(text: str) -> str:
    """A message with its numbers and quoted parts blanked, to group alike failures."""
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "'_'", text)
    return re.sub(r"-?\d+(\.\d+)?(e[-+]?\d+)?", "N", text)[:160]


def _wrote(stdout: str, folder: Path) -> list:
    """The files a successful run says it wrote."""
    paths = []
    for line in stdout.splitlines():
        m = re.fullmatch(r"wrote (\d+) frames and timing\.csv to (.+)", line)
        if m:
            d = folder / m.group(2)
            paths += [d / f"frame_{i:04d}.png" for i in range(int(m.group(1)))] + [d / "timing.csv"]
            continue
        m = re.fullmatch(r"wrote the image comparison to (.+)", line)
        if m:
            continue
        m = re.fullmatch(r"wrote (.+)", line)
        if m:
            paths.append(folder / m.group(1))
    return paths


def readable(path: Path) -> str | None:
    """None when ``path`` is a complete file of its type, else what is wrong."""
    if not path.is_file():
        return "missing"
    if path.stat().st_size == 0:
        return "empty"
    suffix = path.suffix.lower()
    try:
        if suffix in (".exr", ".png"):
            import OpenImageIO as oiio

            inp = oiio.ImageInput.open(str(path))
            if inp is None:
                return f"OpenImageIO cannot open it: {oiio.geterror()}"
            try:
                pixels = inp.read_image()
            finally:
                inp.close()
            if pixels is None or pixels.size == 0:
                return "OpenImageIO reads no pixels"
        elif suffix == ".npy":
            a = np.load(path, allow_pickle=False)
            if a.size == 0:
                return "an empty array"
        elif suffix in (".csv", ".md", ".txt"):
            if not path.read_text(encoding="utf-8").strip():
                return "no text"
        elif suffix == ".json":
            json.loads(path.read_text(encoding="utf-8"))
    except Exception as exc:  # noqa: BLE001 (any reader error means the file is broken)
        return f"unreadable: {type(exc).__name__}: {exc}"
    return None


def judge(case: Case, raw: dict, folder: Path, before: set) -> Outcome:
    out = Outcome(case, raw.get("rc"), raw.get("stdout", ""), raw.get("stderr", ""))

    def fail(kind, detail, signature):
        out.failure = Failure(kind, detail, f"{kind}: {signature}")
        return out

    if raw.get("hang"):
        return fail("hang", "no answer in the time limit", case.argv[0] if case.argv else "load_dict")
    if "died" in raw:
        rc = raw["died"]
        name = signal.Signals(-rc).name if rc < 0 and -rc in signal.Signals._value2member_map_ else f"exit {rc}"
        return fail("crash", f"the process ended ({name})", name)
    if raw.get("traceback"):
        tb = raw["traceback"]
        return fail("traceback", tb, f"{_generic(_last_line(tb).split(':', 1)[0])} at {_where(tb)}")
    new = _files(folder) - before
    hidden = sorted(str(p) for p in new if any(part.startswith(".") for part in p.parts))
    if out.rc == 0:
        wrote = _wrote(out.stdout, folder)
        out.outputs = wrote
        if case.argv is not None and not wrote:
            return fail("missing output", "exit 0 but no file is reported written", case.argv[0])
        for p in wrote:
            problem = readable(p)
            if problem:
                return fail("partial file", f"{p.relative_to(folder)}: {problem}", f"{case.argv[0]} {p.suffix}")
        for p in sorted(new):
            if not any(part.startswith(".") for part in p.parts):
                problem = readable(folder / p)
                if problem:
                    return fail("partial file", f"{p}: {problem}", f"{case.argv[0]} {p.suffix}")
        if hidden:
            return fail("stray temporary", f"left {hidden}", case.argv[0] if case.argv else "load_dict")
        return out
    if out.rc == 2:
        lines = [line for line in out.stderr.splitlines() if line.strip()]
        errors = [line for line in lines if line.startswith("oclgi: error: ")]
        others = [line for line in lines if not line.startswith(("oclgi: error: ", "oclgi: warning: "))]
        if len(errors) != 1 or others or lines[-1] != errors[0]:
            first = (others or errors or ["(no stderr)"])[0]
            return fail("multi-line error", f"{len(lines)} stderr lines, {len(errors)} error lines: {first[:200]}",
                        _generic(first))
        if re.search(r"^wrote ", out.stdout, re.M):
            return fail("partial file", f"exit 2 after reporting {out.stdout.split(chr(10))[0][:200]!r}",
                        f"{case.argv[0] if case.argv else 'load_dict'} wrote then failed")
        if new:
            kind = "stray temporary" if hidden and len(hidden) == len(new) else "partial file"
            return fail(kind, f"exit 2 left {sorted(map(str, new))}: {errors[0][:200]}",
                        f"{case.argv[0] if case.argv else 'load_dict'} {_generic(errors[0])}")
        return out
    last = _last_line(out.stderr)
    return fail("bad exit status", f"exit {out.rc}: {last[:200]}", f"exit {out.rc} {_generic(last)}")
