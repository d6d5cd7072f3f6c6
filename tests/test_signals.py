"""Signals and streams: Ctrl-C at any moment ends the command with one line
and status 130, a SIGINT ignored at start stays ignored (kernel builds
included), and a closed or full stdout ends without a traceback (progress on each kind
of stream: tests/test_progress.py).

Commands run in subprocesses, as a user runs them; SIGINT is sent the way a
terminal sends Ctrl-C.
"""

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from conftest import ROOT

BOX = ROOT / "scenes" / "cornell_box.toml"
INTERRUPTED = "oclgi: interrupted\n"


def _env(**extra):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env.update(extra)
    return env


def _terminal_job(ignore_sigint=False):
    """A child's preexec_fn: as a terminal's job, SIGINT at its default (or
    ignored, as a background job's), whatever this test process inherited
    (a worker of the parallel suite may hold it ignored or blocked)."""
    def pre():
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        signal.signal(signal.SIGINT, signal.SIG_IGN if ignore_sigint else signal.SIG_DFL)
    return pre


def _start(cwd, *args, env=None, ignore_sigint=False, stdout=subprocess.PIPE, code=None):
    cmd = [sys.executable, "-c", code] if code else [sys.executable, "-m", "oclgi", *map(str, args)]
    return subprocess.Popen(cmd, cwd=cwd, env=env or _env(), stdout=stdout, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_terminal_job(ignore_sigint))


def _render(out, photons, size, method="detp"):
    # --plain: the method's own estimate, whose run these tests time and interrupt (the command's
    # default estimate is tests/test_render_preset.py's and tests/test_checkpoint.py's)
    return ("render", BOX, "--method", method, "--photons", photons, "--width", size, "--height", size,
            "--plain", "-o", out, "--quiet")


# -- Ctrl-C during start-up ------------------------------------------------------

# The command as the console script runs it (`oclgi = oclgi.cli:main`) and as
# `python -m oclgi` does, with a Ctrl-C arriving while MODULE is imported:
# an import hook sends the SIGINT, so the moment is exact.
_INTERRUPTING_IMPORT = """
import os, signal, sys
class Hook:
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # the signal is handled between two bytecodes
                pass
        return None
sys.meta_path.insert(0, Hook())
sys.argv = ["oclgi", "info"]
{entry}
"""
ENTRIES = {
    "console script": "from oclgi.cli import main\nsys.exit(main())",
    "python -m": "import runpy\nrunpy.run_module('oclgi', run_name='__main__', alter_sys=True)",
}


@pytest.mark.parametrize("entry", ENTRIES)
@pytest.mark.parametrize("module", ["numpy", "pyopencl"])
def test_ctrl_c_while_importing_is_one_line_and_130(tmp_path, entry, module):
    p = _start(tmp_path, code=_INTERRUPTING_IMPORT.format(module=module, entry=ENTRIES[entry]))
    out, err = p.communicate(timeout=120)
    assert (p.returncode, err) == (130, INTERRUPTED)
    assert out == ""


# -- Ctrl-C during a run -----------------------------------------------------------

def _wait_then_interrupt(p, delay, repeat=False):
    """SIGINT after ``delay`` s (again every 20 ms until the process ends if
    ``repeat``); returns (seconds from the first SIGINT to the exit, stdout, stderr)."""
    time.sleep(delay)
    assert p.poll() is None, "the run ended before it could be interrupted"
    t0 = time.perf_counter()
    p.send_signal(signal.SIGINT)
    while repeat and p.poll() is None:
        time.sleep(0.02)
        try:
            p.send_signal(signal.SIGINT)
        except ProcessLookupError:
            break
    try:
        out, err = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:  # still running: the SIGINT waits for the kernel
        p.kill()
        out, err = p.communicate()
    return time.perf_counter() - t0, out, err


@pytest.fixture(scope="module")
def warm_detp(tmp_path_factory):
    """A tiny plain-DETP render first, so that the long runs below find their
    kernels compiled and are inside a kernel when the SIGINT comes."""
    d = tmp_path_factory.mktemp("warm")
    p = _start(d, *_render(d / "w.exr", 2000, 8))
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err


# Plain DETP over 128 x 128 pixels: one batch of 349,525 paths (the default
# batch) is tens of seconds of one kernel launch when not sliced (over 100 s
# on 2 cores); tracing it (about 2 s) is over by the SIGINT.
# A plain-DETP render of about 13 s on a quiet 2-core machine (9 s at 340k
# photons once the scene trees got faster: a SIGINT at 6 s then raced the
# run's end), interrupted well inside it; on a slow or loaded machine the
# SIGINT may land in start-up, which must end the same way.
LONG_RUN = dict(photons=500_000, size=128)
SIGINT_AT = 3.0


def test_ctrl_c_during_a_long_kernel_exits_within_a_second(tmp_path, warm_detp):
    out_file = tmp_path / "long.exr"
    p = _start(tmp_path, *_render(out_file, **LONG_RUN))
    latency, out, err = _wait_then_interrupt(p, SIGINT_AT)
    assert (p.returncode, err) == (130, INTERRUPTED)
    assert latency < 1.5, f"{latency:.2f} s from SIGINT to exit"
    assert not list(tmp_path.iterdir()), "an interrupted run left files"


def test_repeated_ctrl_c_is_still_one_line_and_130(tmp_path, warm_detp):
    p = _start(tmp_path, *_render(tmp_path / "long.exr", **LONG_RUN))
    _, out, err = _wait_then_interrupt(p, SIGINT_AT, repeat=True)
    assert (p.returncode, err) == (130, INTERRUPTED)
    assert not list(tmp_path.iterdir())


def test_ctrl_c_during_a_cold_kernel_build(tmp_path):
    """Interrupted while PoCL compiles (an empty kernel cache): one line, 130,
    and the cache it leaves serves the next run."""
    cache = tempfile.mkdtemp(dir=tmp_path, prefix="pocl-")
    env = _env(POCL_CACHE_DIR=cache)
    p = _start(tmp_path, *_render(tmp_path / "a.exr", 2000, 8, method="detp_disc_index"), env=env)
    # The SIGINT comes as PoCL starts writing the first program into the
    # cache: inside the cold builds, whatever the machine's speed (a fixed
    # delay could land after a quick machine's whole run).
    deadline = time.monotonic() + 120
    while not any(Path(cache).rglob("*")) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    _, out, err = _wait_then_interrupt(p, 0)
    assert (p.returncode, err) == (130, INTERRUPTED)
    again = _start(tmp_path, *_render(tmp_path / "a.exr", 2000, 8, method="detp_disc_index"), env=env)
    out, err = again.communicate(timeout=300)
    assert (again.returncode, err) == (0, "")
    assert (tmp_path / "a.exr").is_file()


def test_a_run_started_with_sigint_ignored_ignores_it_during_cold_builds(tmp_path):
    """`nohup oclgi ... &`: SIGINT is ignored from the start. PoCL's compiler
    installs a SIGINT handler of its own during a build; a SIGINT then used
    to abort the build. Here SIGINTs keep coming for the whole cold run."""
    cache = tempfile.mkdtemp(dir=tmp_path, prefix="pocl-")
    out_file = tmp_path / "bg.exr"
    p = _start(tmp_path, *_render(out_file, 2000, 8, method="detp_disc_index"),
               env=_env(POCL_CACHE_DIR=cache), ignore_sigint=True)
    time.sleep(0.5)
    while p.poll() is None:
        try:
            p.send_signal(signal.SIGINT)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    out, err = p.communicate(timeout=300)
    assert (p.returncode, err) == (0, "")
    assert out_file.is_file() and out_file.with_suffix(".png").is_file()


# -- standard output going away ----------------------------------------------------

def test_closed_stdout_pipe_ends_quietly_with_141(tmp_path):
    """`oclgi render ... | head -0`: the reader is gone before the "wrote" lines."""
    r, w = os.pipe()
    os.close(r)
    try:
        p = _start(tmp_path, *_render(tmp_path / "p.exr", 2000, 8, method="detp_disc_index"), stdout=w)
    finally:
        os.close(w)
    _, err = p.communicate(timeout=300)
    assert (p.returncode, err) == (141, "")
    assert (tmp_path / "p.exr").is_file() and (tmp_path / "p.png").is_file()


def test_help_into_a_closed_pipe_ends_as_a_run_does(tmp_path):
    """argparse drops the write error of --help itself; the status is still
    the closed pipe's, as for any other output."""
    r, w = os.pipe()
    os.close(r)
    try:
        p = _start(tmp_path, "render", "--help", stdout=w)
    finally:
        os.close(w)
    _, err = p.communicate(timeout=120)
    assert (p.returncode, err) == (141, "")


def test_full_stdout_is_one_line_and_status_2(tmp_path):
    with open("/dev/full", "w") as full:
        p = _start(tmp_path, *_render(tmp_path / "f.exr", 2000, 8, method="detp_disc_index"), stdout=full)
        _, err = p.communicate(timeout=300)
    assert p.returncode == 2
    assert err == "oclgi: error: cannot write to standard output: No space left on device\n"
    assert (tmp_path / "f.exr").is_file()


def test_closed_stderr_runs_as_with_stderr_to_the_null_device(tmp_path):
    """`2>&-`: the command runs and writes as ever (its messages go nowhere);
    an input error still exits 2 and writes nothing; no file takes
    descriptor 2 (a compiler's diagnostics would land in it)."""
    def closed_stderr():
        os.close(2)

    ok = subprocess.run([sys.executable, "-m", "oclgi", *map(str, _render(tmp_path / "s.exr", 2000, 8))],
                        cwd=tmp_path, stdout=subprocess.PIPE, stderr=None, preexec_fn=closed_stderr, timeout=300)
    assert ok.returncode == 0 and ok.stdout.decode().split() == ["wrote", str(tmp_path / "s.exr"), "wrote",
                                                                 str(tmp_path / "s.png")]
    bad = subprocess.run([sys.executable, "-m", "oclgi", *map(str, _render(tmp_path / "b.exr", 0, 8))],
                         cwd=tmp_path, stdout=subprocess.PIPE, stderr=None, preexec_fn=closed_stderr, timeout=300)
    assert bad.returncode == 2 and bad.stdout == b"" and not (tmp_path / "b.exr").exists()
    assert (tmp_path / "s.exr").read_bytes()[:4] == b"v/1\x01"  # an EXR, with nothing else written into it


SWALLOWING = r"""
import os, signal, sys
import trimesh
real = trimesh.load
def load(*args, **kwargs):
    try:  # a Ctrl-C while trimesh works, swallowed as trimesh swallows one during its optional imports
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):
            pass
    except BaseException:
        pass
    return real(*args, **kwargs)
trimesh.load = load
from oclgi.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_ctrl_c_a_library_swallows_still_stops_the_run(tmp_path):
    """trimesh catches every exception of an optional import, KeyboardInterrupt
    included, and goes on: a Ctrl-C in those moments (0.5-1 s after start)
    ran the whole render and exited 0. It stops it, in one line and 130."""
    scene = ROOT / "scenes" / "cornell_bunny.toml"
    p = subprocess.run([sys.executable, "-c", SWALLOWING, "render", str(scene), "--photons", "2000000", "--width",
                        "16", "--height", "16", "--plain", "-o", str(tmp_path / "x.exr")], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300, preexec_fn=_terminal_job())
    assert (p.returncode, p.stderr) == (130, "oclgi: interrupted\n"), p.stderr[-2000:]
    assert not list(tmp_path.glob("x.*")) and not list(tmp_path.glob(".x.*"))
