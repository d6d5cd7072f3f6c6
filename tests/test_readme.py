"""The README's code runs as written, from a folder that holds the
repository's scenes (as a user's checkout does), and makes what it says.

Python blocks (```python) run in order, in one namespace. Shell blocks
(```sh) run each in one bash (errors stop it), the ``oclgi`` and ``mpirun``
of this environment first on the PATH, except by this rule: a block whose
commands are all ``make`` targets or install commands (``pip``,
``apt-get``) is not run, since those set up the machine and ``make test``
runs this suite; nor is a block that starts a server (``oclgi view``, which
serves until Ctrl-C: tests/test_viewer_cli.py runs it and stops it). A usage synopsis, with placeholders, is a ```text block
and is not code. The README's commands are cheap enough to run as they
stand (it says so where its counts are small).
"""

import contextlib
import io
import os
import re
import subprocess
import sys

from conftest import ROOT

BLOCK = re.compile(r"^```python\n(.*?)^```", re.M | re.S)
SHELL = re.compile(r"^```sh\n(.*?)^```", re.M | re.S)
SETUP = ("make", "pip", "pip3", "apt-get", "apt")  # set up the machine: not run (the module's rule)


def _blocks():
    return BLOCK.findall((ROOT / "README.md").read_text())


def _commands(block: str) -> list[str]:
    return [line.split("#", 1)[0].strip() for line in block.splitlines() if line.split("#", 1)[0].strip()]


def _is_setup(block: str) -> bool:
    words = [c.split()[0] for c in _commands(block)]
    return all(w in SETUP or w.endswith("/pip") for w in words) or "python -m pip" in block


def _is_server(block: str) -> bool:
    return any(c.split()[:2] == ["oclgi", "view"] for c in _commands(block))


def _shell_blocks():
    return [b for b in SHELL.findall((ROOT / "README.md").read_text()) if not (_is_setup(b) or _is_server(b))]


def test_the_shell_blocks_are_run_or_set_up():
    every = SHELL.findall((ROOT / "README.md").read_text())
    run = _shell_blocks()
    assert len(run) >= 2 and len(every) - len(run) >= 1  # the two-command block is set-up
    assert all(c.split()[0] in ("oclgi", "mpirun", "printf") for b in run for c in _commands(b))


def test_every_shell_block_runs_as_written(tmp_path):
    (tmp_path / "scenes").symlink_to(ROOT / "scenes")
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([os.path.dirname(sys.executable), env.get("PATH", "")])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env.setdefault("OCLGI_KERNEL_DIR", str(ROOT / "kernels"))
    said = ""
    for i, block in enumerate(_shell_blocks(), 1):
        proc = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", block], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0 and "Traceback" not in proc.stderr, f"shell block {i}:\n{block}\n{proc.stderr}"
        said += proc.stdout + proc.stderr  # the summary lines are on stderr
    assert "300,000 photons" in said  # the resumed run with --more: 2e5 + 1e5
    assert "| 2 ranks" in said  # mpirun's runs, split over the ranks
    out = tmp_path / "out"
    for name in ("run.npz", "cornell_box.exr", "cornell_box.png", "cornell.exr", "e.npy", "study/study.md"):
        assert (out / name).is_file(), name


def test_the_readme_has_python_blocks():
    assert len(_blocks()) >= 5


def test_every_python_block_runs(tmp_path, monkeypatch):
    (tmp_path / "scenes").symlink_to(ROOT / "scenes")
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "readme"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for i, code in enumerate(_blocks(), 1):
            exec(compile(code, f"README.md python block {i}", "exec"), namespace)  # noqa: S102
    assert "detp_disc_index: 200,000 photons" in out.getvalue()  # the first block's summary
    assert (tmp_path / "out" / "cornell.exr").is_file() and (tmp_path / "out" / "cornell.png").is_file()
    assert (tmp_path / "out" / "study" / "study.md").is_file()
    assert (tmp_path / "out" / "cmp" / "comparison.json").is_file()
    assert namespace["est"].irradiance.shape == (3, 3) and (namespace["est"].irradiance > 0).all()
