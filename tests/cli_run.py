"""Running the ``oclgi`` command the way a user does, in a subprocess, or
in-process (quicker: one import, one kernel cache) through ``oclgi.cli.main``."""

import subprocess
import sys


def run(cwd, *args):
    """``python -m oclgi *args`` in ``cwd`` (None: here); text output captured."""
    return subprocess.run([sys.executable, "-m", "oclgi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def in_process(monkeypatch, capsys, cwd, *args):
    """``oclgi.cli.main(args)`` in ``cwd``, as a CompletedProcess (stdout and
    stderr as captured by pytest's ``capsys``)."""
    from oclgi.cli import main

    monkeypatch.chdir(cwd)
    capsys.readouterr()
    try:
        rc = main([str(a) for a in args])
    except SystemExit as exc:  # argparse
        rc = exc.code
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(args, rc, out, err)
